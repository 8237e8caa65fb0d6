"""A status polled again: lines read before are not parsed again, and a view made from the previous one
(`Status.to_dict(since=…)`) equals a view made from scratch, key order and JSON text included."""

from __future__ import annotations

import json
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from fabwire.xyz import status as status_module
from fabwire.xyz.status import LETTERS, SHARED_LETTERS, Status, changed_fields

DATA = Path(__file__).parent / "data"

VARIANTS: dict[str, tuple[str, ...]] = {
    # letter: wire values, from the captures in tests/xyz/data and the shapes the references give, plus what
    # does not parse, a dash and control characters (kept raw)
    "b": ("20", "--", "60", "x"),
    "c": ("{336,374,377,355,373,371,364,377,356}", "{1,2}", "{a}"),
    "d": ("0,0,0", "45,12,71582788", "100,30,0", "1,2"),
    "e": ("0", "2", "1073807364", "0,0"),
    "f": ("1,200000", "2,100,200", "1,-1", "x"),
    "h": ("1", "x"),
    "i": ("3FM1WPUS5CA6750022", "3F11XPGBXTH5320151"),
    "j": ("9511,0", "9511", "9601,4", "10", "x,1"),
    "k": ("50", "65"),
    "l": ("en", "de"),
    "m": ("0,0,0", "1,2,3"),
    "n": ("mini w          ", "da Vinci 1.1 Plus"),
    "o": ("p8,t1,c1,a+", "p9,t1,c0", "p8,t1,c1,a-"),
    "O": ('{"nozzle":"210","bed":"60"}', '{"nozzle":210,"bed":60}', '{"bed":1}', '{"bed":1.0}', '{"bed":true}',
          '{"bed":NaN}', '{"bed":null}', "[1]"),
    "p": ("dv1MW0A000", "dvF110B000", "dv1JP0A000", "zz"),
    "s": ('{"fm":0,"fd":0,"sd":"yes","button":"no","buzzer":"on"}', '{"buzzer":"off","dr":{"top":"on"}}',
          '{"buzzer":1}', '{"buzzer":1.0}', '{"buzzer":"\\ud800"}', "{"),
    "t": ("1,22,0", "1,215,220", "2,200,210", "1,--,--", "x"),
    "v": ("1.2.3", "1.1.0.19,1.1.7.3,N/A"),
    "w": ("1,PMP6QTH64R1093", "1,--------------", "2,PMP6QTH64R1093,PMP6QTH64R1094"),
    "z": ("245", "250", "x"),
    "G": ('{"a":1}', '{"a":true}'),
    "L": ("1,301080,28581,0", "1,301096,28581,16", "1,69342,21785"),
    "V": ("5.0.9",),
    "W": ('[{"ssid":"a"}]', '{"ssid":"a"}', "[1.0]", "[1]"),
    "X": ("2,GB-0002-0000-TH-68T-0250-28727", "N,x"),
    "4": ('{"wlan":{"ip":"192.168.1.118","ssid":"TUCKER_HOME","channel":"0","rssiValue":"39",'
          '"MAC":"54:8c:a0:06:7e:48"}}', "192.168.1.126", "0.0.0.0"),
    "Z": ('{"file":"a.3w"}', '{"file":"b.3w"}'),
    "q": ("unknown letter", "another"),
}
ODD_LINES = ("b:\x0260", "\x01:5", "ok", "", "$", "e", "bb:1", "t:\x1b[2J")
"""Lines with control characters, without a letter, or not `x:value` at all."""

LINES = [f"{letter}:{value}" for letter, values in VARIANTS.items() for value in values] + list(ODD_LINES)
replies = st.lists(st.sampled_from(LINES), max_size=40)


def test_every_letter_has_variants() -> None:
    assert set(LETTERS) <= set(VARIANTS)


def _same_view(status: Status, since: tuple[Status, dict[str, object]]) -> None:
    fresh = status.to_dict()
    again = status.to_dict(since=since)
    assert again == fresh
    assert list(again) == list(fresh)
    assert list(again["raw"]) == list(fresh["raw"])
    assert json.dumps(again) == json.dumps(fresh)  # 1, 1.0 and true are equal in Python, not on the wire


@settings(max_examples=400)
@given(first=replies, second=replies, partial=st.booleans())
def test_a_view_since_an_earlier_one_equals_one_from_scratch(first: list[str], second: list[str],
                                                             partial: bool) -> None:
    before = Status.parse(first)
    after = before.update(second) if partial else Status.parse(second)
    _same_view(after, (before, before.to_dict()))


@settings(max_examples=200)
@given(polls=st.lists(replies, min_size=2, max_size=6))
def test_views_chained_poll_after_poll_stay_equal(polls: list[list[str]]) -> None:
    status = Status.parse(polls[0])
    view = status.to_dict()
    for reply in polls[1:]:
        nxt = Status.parse(reply)
        view = nxt.to_dict(since=(status, view))
        assert view == nxt.to_dict()
        status = nxt


@given(reply=replies)
def test_the_same_reply_read_twice_is_equal_and_unchanged(reply: list[str]) -> None:
    one, two = Status.parse(reply), Status.parse(reply)
    assert one == two
    assert changed_fields(one, two) == frozenset()


def test_a_changed_line_is_the_only_change() -> None:
    reply = [line for line in (DATA / "mini_w_wifi.txt").read_text().splitlines() if line and line != "$"]
    before = Status.parse(reply)
    after = Status.parse([("t:1,23,0" if line.startswith("t:") else line) for line in reply])
    assert changed_fields(before, after) == {"temperatures"}
    view = after.to_dict(since=(before, before.to_dict()))
    assert (view["extruder_c"], view["raw"]["t"]) == (23, "1,23,0")


def test_json_values_are_never_shared_between_statuses() -> None:
    """A JSON object is mutable: each status has its own, while numbers and tuples may be shared."""
    reply = ['s:{"buzzer":"on"}', 'O:{"bed":"60"}', "t:1,22,0", "c:{1,2}"]
    one, two = Status.parse(reply), Status.parse(reply)
    assert one.settings == two.settings
    assert one.settings is not two.settings
    assert one.targets is not two.targets
    assert not {"s", "O", "G", "W", "Z"} & SHARED_LETTERS
    assert changed_fields(one, two) == frozenset()


def test_json_written_differently_is_a_change() -> None:
    for a, b in [('{"bed":1}', '{"bed":1.0}'), ('{"bed":1}', '{"bed":true}'), ('{"a":1,"b":2}', '{"b":2,"a":1}'),
                 ('{"bed":NaN}', '{"bed":null}'), ('{"bed":Infinity}', '{"bed":null}')]:
        assert changed_fields(Status.parse([f"O:{a}"]), Status.parse([f"O:{b}"])) == {"targets"}, (a, b)


def test_control_characters_and_odd_lines_read_as_before() -> None:
    status = Status.parse(["b:\x0260", "\x01:5", "ok", "", "e", "bb:1", "j:9511,0"])
    assert status.order == ("b", "j")
    assert status.unparsed == {"b": "\\x0260"}
    assert status.extra == {}
    assert status.to_dict()["raw"] == {"b": "\\x0260", "j": "9511,0"}


def test_the_line_memory_is_bounded() -> None:
    for n in range(3 * status_module.LINE_MEMORY):
        Status.parse([f"L:1,{n},0,0"])
    assert len(status_module._recent) + len(status_module._older) <= 2 * status_module.LINE_MEMORY


def test_a_letter_that_turns_from_unreadable_to_dashed_is_dashed_only() -> None:
    """A partial query merges into the last status: `b:x` (not a number) then `b:--` leaves `b` dashed."""
    merged = Status.parse(["b:x", "j:9511,0"]).update(["b:--"])
    assert merged.lines() == Status.parse(["b:--", "j:9511,0"]).lines() == ["b:--", "j:9511,0"]
