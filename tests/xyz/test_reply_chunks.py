"""A status reply read however the bytes arrive: all at once, line by line or cut anywhere, the reader gives the
same events and counts the same noise; the reply's lines are its `x:value` lines, in order (trailing blanks cut)."""

from __future__ import annotations

import itertools

from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.xyz import protocol as p
from fabwire.xyz.replies import ReplyReader

STATUS_LINES = ["j:9511,0", "t:1,22,0", "b:--", 'O:{"bed":"60"}', "L:1,301096,28581,16", "n:mini w          ",
                "x:unknown letter", "4:192.168.1.126", "e:0"]
OTHER_LINES = ['load:{"stat":"heat","extemp":"24"}', "ok", "ok 12", "", "garbage", "E3", "\x1b[2J"]


def _events(link: p.Link, command: p.Command, wire: bytes, cuts: list[int]) -> tuple[list[object], int]:
    reader = ReplyReader(link)
    reader.send(command, now=0.0)
    events: list[object] = []
    edges = [0, *sorted(set(cuts)), len(wire)]
    for start, end in itertools.pairwise(edges):
        reader.receive(wire[start:end], 0.01)
        while (event := reader.next_event(0.01)) is not None:
            events.append(event)
    while (event := reader.next_event(100.0)) is not None:
        events.append(event)
    return events, reader.noise


@settings(max_examples=300)
@given(lines=st.lists(st.sampled_from(STATUS_LINES + OTHER_LINES), max_size=30),
       link=st.sampled_from([p.Link.SERIAL, p.Link.WIFI]), letters=st.sampled_from(["a", "jt", "j"]),
       crlf=st.booleans(), data=st.data())
def test_any_cut_gives_the_same_events(lines: list[str], link: p.Link, letters: str, crlf: bool,
                                       data: st.DataObject) -> None:
    end = b"\r\n" if crlf else b"\n"
    wire = b"".join(line.encode("latin-1") + end for line in [*lines, "$"])
    command = p.Query(letters)
    whole = _events(link, command, wire, [])
    cuts = data.draw(st.lists(st.integers(0, len(wire)), max_size=12))
    assert _events(link, command, wire, cuts) == whole
    assert _events(link, command, wire, list(range(len(wire)))) == whole


def test_a_status_reply_keeps_its_letter_lines_in_order() -> None:
    wire = "".join(f"{line}\n" for line in [*STATUS_LINES, "$"]).encode("latin-1")
    for link in (p.Link.SERIAL, p.Link.WIFI):
        events, noise = _events(link, p.Query("a"), wire, [7, 30])
        assert [e.lines for e in events] == [tuple(line.rstrip(" ") for line in STATUS_LINES)]  # type: ignore[attr-defined]
        assert noise == 0


def _line_by_line(link: p.Link, command: p.Command, wire: bytes) -> tuple[list[object], int, str | None]:
    """The reader's rule for one line (`_note`), applied to each line in turn: what reading them in one pass
    must give."""
    reader = ReplyReader(link)
    reader.send(command, now=0.0)
    events: list[object] = []
    for line in wire.decode("latin-1").split("\n")[:-1]:
        reader._note(line.rstrip("\r "))
        while (event := reader.next_event(0.01)) is not None:
            events.append(event)
    while (event := reader.next_event(100.0)) is not None:
        events.append(event)
    return events, reader.noise, reader.noise_sample


@settings(max_examples=300)
@given(lines=st.lists(st.one_of(st.sampled_from(STATUS_LINES + OTHER_LINES),
                                st.text(alphabet=": \r\t$Eokaj0{}\"x\x00\xff", max_size=8)), max_size=40),
       bulk=st.integers(0, 300), link=st.sampled_from([p.Link.SERIAL, p.Link.WIFI]),
       letters=st.sampled_from(["a", "jt"]))
def test_reading_lines_in_one_pass_is_reading_them_one_by_one(lines: list[str], bulk: int, link: p.Link,
                                                               letters: str) -> None:
    """Control characters, blanks and colons anywhere, and status replies past the reader's bound (256 lines)."""
    wire = b"".join(line.encode("latin-1") + b"\n" for line in [*(["t:1,22,0 \r"] * bulk), *lines, "$"])
    command = p.Query(letters)
    reader = ReplyReader(link)
    reader.send(command, now=0.0)
    events: list[object] = []
    reader.receive(wire, 0.01)
    while (event := reader.next_event(0.01)) is not None:
        events.append(event)
    while (event := reader.next_event(100.0)) is not None:
        events.append(event)
    assert (events, reader.noise, reader.noise_sample) == _line_by_line(link, command, wire)
