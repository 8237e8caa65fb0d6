"""Every accepted address form, and a specific error for each malformed one."""

from __future__ import annotations

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from fabwire.devices import LINEUS, MMU, XYZ
from fabwire.errors import InputError
from fabwire.transport import Endpoint, parse_url


@pytest.mark.parametrize(
    ("text", "kind", "expected"),
    [
        ("192.168.1.50", XYZ, Endpoint("tcp", host="192.168.1.50", port=9100)),
        ("line-us.local", LINEUS, Endpoint("tcp", host="line-us.local", port=1337)),
        ("localhost:2000", XYZ, Endpoint("tcp", host="localhost", port=2000)),
        ("tcp://127.0.0.2:9100", XYZ, Endpoint("tcp", host="127.0.0.2", port=9100)),
        ("tcp://printer", XYZ, Endpoint("tcp", host="printer", port=9100)),
        ("TCP://printer:1/", XYZ, Endpoint("tcp", host="printer", port=1)),
        ("[::1]:1337", LINEUS, Endpoint("tcp", host="::1", port=1337)),
        ("tcp://[::1]", LINEUS, Endpoint("tcp", host="::1", port=1337)),
        ("::1", LINEUS, Endpoint("tcp", host="::1", port=1337)),
        ("/dev/ttyACM0", XYZ, Endpoint("serial", path="/dev/ttyACM0")),
        ("serial:///dev/ttyUSB1", MMU, Endpoint("serial", path="/dev/ttyUSB1")),
        ("  /dev/pts/3 ", MMU, Endpoint("serial", path="/dev/pts/3")),
        ("sim://mmu", MMU, Endpoint("sim", host="mmu")),
        ("COM3", MMU, Endpoint("serial", path="COM3")),
        ("com12", XYZ, Endpoint("serial", path="com12")),
        ("sim://xyz?model=nano&speed=50", XYZ, Endpoint("sim", host="xyz", options={"model": "nano", "speed": "50"})),
        ("sim://", LINEUS, Endpoint("sim", host="lineus")),
    ],
)
def test_accepted_forms(text: str, kind: object, expected: Endpoint) -> None:
    assert parse_url(text, kind) == expected  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("text", "kind", "reason"),
    [
        ("", XYZ, "empty"),
        ("printer:", XYZ, "empty port"),
        ("printer:abc", XYZ, "not a number"),
        ("printer:70000", XYZ, "outside 1-65535"),
        ("printer:0", XYZ, "outside 1-65535"),
        ("tcp://", XYZ, "no host"),
        ("tcp://printer/x", XYZ, "no path"),
        ("bad host!", XYZ, "not a valid host"),
        ("serial://dev/ttyACM0", XYZ, "absolute device path"),
        ("ftp://printer", XYZ, "unknown scheme 'ftp'"),
        ("[::1", LINEUS, "unclosed"),
        ("sim://mmu/path", MMU, "no path"),
        ("mmu-box", MMU, "no default TCP port"),
    ],
)
def test_malformed_addresses_say_what_is_wrong(text: str, kind: object, reason: str) -> None:
    with pytest.raises(InputError, match="malformed device address") as info:
        parse_url(text, kind)  # type: ignore[arg-type]
    assert reason in str(info.value)


def test_endpoint_url_is_canonical() -> None:
    assert parse_url("printer", XYZ).url == "tcp://printer:9100"
    assert parse_url("::1", LINEUS).url == "tcp://[::1]:1337"
    assert parse_url("/dev/ttyACM0", XYZ).url == "serial:///dev/ttyACM0"
    assert parse_url("sim://xyz?speed=5", XYZ).url == "sim://xyz?speed=5"


@settings(max_examples=400, deadline=None)
@given(text=st.one_of(
    st.text(max_size=60),
    st.builds(lambda host, port: f"{host}:{port}", st.sampled_from(["127.0.0.1", "host", "[::1]", "tcp://h"]),
              st.one_of(st.integers(-10, 10**6).map(str), st.text(alphabet="0123456789٣²", min_size=1, max_size=30),
                        st.just("9" * 5000))),
))
@example(text="0000000000000\x1f" * 11 + "\U00012544" * 40)  # a host of wide characters, quoted in the message
@example(text="tcp://h:1/?" + "\U00012544" * 60)
@example(text="\U00012544" * 50 + "://h")
def test_any_address_text_parses_or_is_one_short_input_error(text: str) -> None:
    message = ""
    try:
        endpoint = parse_url(text, XYZ)
    except InputError as exc:
        message = str(exc)
    if message:
        assert len(message) < 400
        assert "\n" not in message
    else:
        assert endpoint.scheme != "tcp" or 1 <= endpoint.port <= 65535


def test_a_port_of_thousands_of_digits_is_refused_briefly() -> None:
    with pytest.raises(InputError, match=r"port '999999999999…' is too long to be a port"):
        parse_url("127.0.0.1:" + "9" * 5000, XYZ)
    with pytest.raises(InputError, match="port '٣' is not a number"):
        parse_url("127.0.0.1:٣", XYZ)
