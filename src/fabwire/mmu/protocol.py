"""Sans-IO codec for the MMU3 serial protocol, both roles, exact to the byte.

Requests (`T1*cf`) go printer → MMU, responses (`T1 A*27`) come back. Numbers are minimal lowercase hex; the
CRC-8 (poly 0x07) covers the binary field values, not the text. The two decoders reproduce the firmware's
byte-at-a-time automata, quirks included: over-long numbers keep their low bits, an empty number is 0, uppercase
hex is an error, `\\r` ends a message like `\\n`, and after an error everything up to the next newline is eaten —
so a bad line also costs the message after it when the error was only noticed at its newline.

Two fast paths decode well-formed lines: lines already seen come from a memo; a run of well-formed replies is
cut into fields with bytes methods and checked against CRC tables in one pass over the received block. Anything
else goes through the exact automaton, so all three give the same events.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from typing import ClassVar, Final

from fabwire.errors import LocalProtocolError, RemoteProtocolError
from fabwire.mmu.crc import CRC_TABLE as CRC_TABLE  # re-exported: the codec is where callers look
from fabwire.mmu.crc import crc8 as crc8
from fabwire.mmu.crc import request_crc as request_crc
from fabwire.mmu.crc import response_crc as response_crc

REQUEST_CODES: Final = "QTLMUXPSBEWKFfHR"
PARAM_CODES: Final = "ARPEFB"
COMMAND_CODES: Final = "TLUEKHM"
"""Requests the MMU plans as a command (busy rule, `currentCommand` echo in Q0 replies)."""


# ---------------------------------------------------------------------------------------------- messages


def _check(name: str, value: int, bits: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value < (1 << bits):
        raise LocalProtocolError(f"{name} must be an integer from 0 to {(1 << bits) - 1}, not {value!r}")


@dataclass(frozen=True, slots=True)
class Request:
    """A printer → MMU request; `value` is the 8-bit field after the code."""

    code: ClassVar[str] = "?"
    value: int = 0

    def __post_init__(self) -> None:
        _check(f"{type(self).__name__} value", self.value, 8)

    @property
    def value2(self) -> int:
        return 0

    def __str__(self) -> str:
        return f"{self.code}{self.value:x}"


@dataclass(frozen=True, slots=True)
class Query(Request):
    code: ClassVar[str] = "Q"


@dataclass(frozen=True, slots=True)
class ToolChange(Request):
    code: ClassVar[str] = "T"


@dataclass(frozen=True, slots=True)
class Load(Request):
    code: ClassVar[str] = "L"


@dataclass(frozen=True, slots=True)
class Mode(Request):
    """0 = normal (SpreadCycle), anything else = stealth."""

    code: ClassVar[str] = "M"


@dataclass(frozen=True, slots=True)
class Unload(Request):
    code: ClassVar[str] = "U"


@dataclass(frozen=True, slots=True)
class Reset(Request):
    """0 reboots; 42 erases the EEPROM first. Never answered."""

    code: ClassVar[str] = "X"


@dataclass(frozen=True, slots=True)
class FindaQuery(Request):
    code: ClassVar[str] = "P"


@dataclass(frozen=True, slots=True)
class Version(Request):
    """`value` is a register address: 0 major, 1 minor, 2 revision, 3 build."""

    code: ClassVar[str] = "S"


@dataclass(frozen=True, slots=True)
class ButtonPress(Request):
    code: ClassVar[str] = "B"


@dataclass(frozen=True, slots=True)
class Eject(Request):
    code: ClassVar[str] = "E"


@dataclass(frozen=True, slots=True)
class Cut(Request):
    code: ClassVar[str] = "K"


@dataclass(frozen=True, slots=True)
class FilamentType(Request):
    """Decoded by the MMU but never answered."""

    code: ClassVar[str] = "F"


@dataclass(frozen=True, slots=True)
class FSensorState(Request):
    """The printer's filament sensor: 0 off; 1, 2 and 3 all count as on."""

    code: ClassVar[str] = "f"


@dataclass(frozen=True, slots=True)
class Home(Request):
    code: ClassVar[str] = "H"


@dataclass(frozen=True, slots=True)
class Read(Request):
    """`value` is the register address."""

    code: ClassVar[str] = "R"


@dataclass(frozen=True, slots=True)
class Write(Request):
    """`value` is the register address, `data` the 16-bit word written."""

    code: ClassVar[str] = "W"
    data: int = 0

    def __post_init__(self) -> None:
        _check("Write address", self.value, 8)
        _check("Write data", self.data, 16)

    @property
    def address(self) -> int:
        return self.value

    @property
    def value2(self) -> int:
        return self.data

    def __str__(self) -> str:
        return f"W{self.value:x} {self.data:x}"


REQUEST_TYPES: Final[dict[str, type[Request]]] = {
    cls.code: cls
    for cls in (Query, ToolChange, Load, Mode, Unload, Reset, FindaQuery, Version, ButtonPress, Eject, Write, Cut,
                FilamentType, FSensorState, Home, Read)
}


def make_request(code: str, value: int = 0, data: int = 0) -> Request:
    cls = REQUEST_TYPES.get(code)
    if cls is None:
        raise LocalProtocolError(f"{code!r} is not an MMU request code (one of {REQUEST_CODES})")
    if cls is Write:
        return Write(value, data)
    if data:
        raise LocalProtocolError(f"only W requests carry a data word, not {code!r}")
    return cls(value)


@dataclass(frozen=True, slots=True)
class Response:
    """An MMU → printer reply: the echoed request (`request_code`, `request_value`), a parameter and its value.

    `value` is None when the text had no digits (acknowledgements); the CRC then counts it as 0.
    """

    param: ClassVar[str] = "?"
    request_code: str
    request_value: int = 0
    value: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.request_code, str) or len(self.request_code) != 1 or \
                self.request_code not in REQUEST_CODES:
            raise LocalProtocolError(f"{self.request_code!r} is not an MMU request code (one of {REQUEST_CODES})")
        _check("response request value", self.request_value, 8)
        if self.value is not None:
            _check(f"{type(self).__name__} value", self.value, 16)

    @property
    def number(self) -> int:
        """The value as the firmware sees it (missing digits = 0)."""
        return self.value or 0

    @property
    def command(self) -> str:
        return f"{self.request_code}{self.request_value:x}"

    def answers(self, request: Request) -> bool:
        return self.request_code == request.code and self.request_value == request.value

    def __str__(self) -> str:
        digits = "" if self.value is None else f"{self.value:x}"
        return f"{self.command} {self.param}{digits}"


@dataclass(frozen=True, slots=True)
class Accepted(Response):
    param: ClassVar[str] = "A"


@dataclass(frozen=True, slots=True)
class Rejected(Response):
    param: ClassVar[str] = "R"


@dataclass(frozen=True, slots=True)
class Processing(Response):
    """The command is running; `value` is a progress code."""

    param: ClassVar[str] = "P"


@dataclass(frozen=True, slots=True)
class CommandError(Response):
    """The command stopped on an error; `value` is an error code."""

    param: ClassVar[str] = "E"


@dataclass(frozen=True, slots=True)
class Finished(Response):
    """The command finished; `value` is a result code (0 OK, 1 cancelled)."""

    param: ClassVar[str] = "F"


@dataclass(frozen=True, slots=True)
class ButtonPressed(Response):
    """A button was pressed on the MMU during a tool change; the printer decides what it means."""

    param: ClassVar[str] = "B"


RESPONSE_TYPES: Final[dict[str, type[Response]]] = {
    cls.param: cls for cls in (Accepted, Rejected, Processing, CommandError, Finished, ButtonPressed)
}


@dataclass(frozen=True, slots=True)
class DecodeError:
    """Bytes the decoder could not accept; `data` is the start of the offending line (at most 32 bytes)."""

    reason: str
    data: bytes = b""

    def exception(self) -> RemoteProtocolError:
        return RemoteProtocolError(f"MMU protocol error: {self.reason} in {self.data!r}")


Message = Request | Response
RequestEvent = Request | DecodeError
ResponseEvent = Response | DecodeError

# ---------------------------------------------------------------------------------------------- encoding

_ENCODED: dict[Message, bytes] = {}
_CACHE_LIMIT = 4096


def encode_request(request: Request) -> bytes:
    if not isinstance(request, Request) or type(request) is Request:
        raise LocalProtocolError(f"cannot encode {request!r} as an MMU request")
    out = _ENCODED.get(request)
    if out is None:
        code, value, value2 = request.code, request.value, request.value2
        crc = request_crc(code, value, value2)
        out = f"{request}*{crc:x}\n".encode()
        if len(_ENCODED) >= _CACHE_LIMIT:
            _ENCODED.clear()
        _ENCODED[request] = out
    return out


def encode_response(response: Response) -> bytes:
    if not isinstance(response, Response) or type(response) is Response:
        raise LocalProtocolError(f"cannot encode {response!r} as an MMU response")
    out = _ENCODED.get(response)
    if out is None:
        crc = response_crc(response.request_code, response.request_value, response.param, response.number)
        out = f"{response}*{crc:x}\n".encode()
        if len(_ENCODED) >= _CACHE_LIMIT:
            _ENCODED.clear()
        _ENCODED[response] = out
    return out


def encode(message: Message) -> bytes:
    if isinstance(message, Request):
        return encode_request(message)
    return encode_response(message)


# ---------------------------------------------------------------------------------------------- decoding

_HEX: Final = tuple(int(chr(b), 16) if chr(b) in "0123456789abcdef" else -1 for b in range(256))
_NEWLINE: Final = (0x0A, 0x0D)
_REQUEST_CODE_BYTES: Final = frozenset(REQUEST_CODES.encode())
_PARAM_CODE_BYTES: Final = frozenset(PARAM_CODES.encode())
_ERROR_SNIPPET = 32
_MEMO_LINE = 24
"""Longest line the fast path memoises: a well-formed message is at most 14 bytes (`T ff E ffff*ff`), and
memoising long ones (legal: leading zeros) would let a peer fill the memo with 4096 lines of any size."""

_FAST_REQUEST = re.compile(rb"([QTLMUXPSBEKFfHR])([0-9a-f]*)\*([0-9a-f]*)")
_FAST_WRITE = re.compile(rb"W([0-9a-f]*) ([0-9a-f]*)\*([0-9a-f]*)")
_FAST_RESPONSE = re.compile(rb"([QTLMUXPSBEWKFfHR])([0-9a-f]*) ([ARPEFB])([0-9a-f]*)\*([0-9a-f]*)")


_SET_CODE: Final = Response.__dict__["request_code"].__set__
_SET_VALUE: Final = Response.__dict__["request_value"].__set__
_SET_NUMBER: Final = Response.__dict__["value"].__set__
"""The slots' own setters: a decoded response is built without re-validating fields the decoder already bounded
(and without the frozen class's `__setattr__`)."""


def _response(cls: type[Response], code: str, value: int, pvalue: int | None) -> Response:
    """Build a decoded response without re-validating fields the decoder already bounded."""
    message = object.__new__(cls)
    _SET_CODE(message, code)
    _SET_VALUE(message, value)
    _SET_NUMBER(message, pvalue)
    return message


_RESPONSE_BLOCK: Final = re.compile(
    rb"(?:[%s][0-9a-f]{0,2} [%s][0-9a-f]{0,4}\*[0-9a-f]{1,2}\n)+" % (REQUEST_CODES.encode(), PARAM_CODES.encode()))
"""A run of replies in the shape the MMU sends (`T1 A1234*27`, minimal lowercase hex, newline-terminated), where
no field is long enough for the automaton's masking to matter; anything else stops the block."""
_PARAM_SPLIT: Final = tuple((b" " + bytes([c]), b" " + bytes([c]) + b" ") for c in PARAM_CODES.encode())
"""`T1 A1234` → `T1 A 1234`: a block's only space precedes the parameter code, so it splits off cleanly."""
_FIELD_SEPARATORS: Final = bytes.maketrans(b"*\n", b"  ")
_PARAMS: Final = {param.encode(): (cls, ord(param)) for param, cls in RESPONSE_TYPES.items()}
_CRC_TEXT: Final = tuple(b"%x" % crc for crc in range(256))
"""Each CRC as the MMU writes it; any other spelling of a CRC (leading zero) leaves the block."""


@functools.cache
def _response_heads() -> dict[bytes, tuple[str, int, int]]:
    """Every request echo a block can start with (code, then no, one or two digits) → code, value, and the reply
    CRC-8 over them (`request_crc` with no data word). 16 × 273 entries, built on first use."""
    heads: dict[bytes, tuple[str, int, int]] = {}
    for code in REQUEST_CODES:
        for value in range(256):
            entry = (code, value, request_crc(code, value))
            heads[b"%c%x" % (ord(code), value)] = entry
            if value < 16:
                heads[b"%c%02x" % (ord(code), value)] = entry
        heads[code.encode()] = heads[code.encode() + b"0"]
    return heads


def _hex(digits: bytes, mask: int) -> int:
    return int(digits, 16) & mask if digits else 0


class _Decoder:
    """Shared plumbing: memo of well-formed lines, error snippets, the line-by-line driver.

    `phantoms` reproduces a quirk of the firmware's response decoder (Prusa-Firmware-MMU `protocol.cpp`
    `DecodeResponse`, the `RequestCode` state's default branch, compiled into the MMU repository's and the printer
    firmwares' codecs): a bad first byte moves to the error state without marking the message, so when the next byte
    is already the newline (`a\\n` right after a valid frame) the decoder reports the previous message complete
    once more — a phantom copy. Off by default: a host that acts on a phantom would count an acknowledgement or a
    finished command twice. The firmware's request decoder marks the message unknown on the same path, so a real
    MMU never repeats a request; the switch on the request side makes a simulated MMU that does, to test hosts
    against it."""

    _START = 0
    _ERROR = 5

    def __init__(self, *, phantoms: bool = False) -> None:
        self._state = self._START
        self._line = bytearray()
        self._memo: dict[bytes, Message] = {}
        self.errors = 0
        """How many error events this decoder has produced."""
        self.phantoms = phantoms
        self._last: Message | None = None
        self._phantom = False
        """The line failed on its first byte and nothing followed yet: its newline repeats `_last`."""

    @property
    def idle(self) -> bool:
        """True between messages (no partial line pending)."""
        return self._state == self._START and not self._line

    def reset(self) -> None:
        self._state = self._START
        self._line.clear()

    def _fail(self, reason: str, events: list[object]) -> None:
        self._phantom = self.phantoms and self._last is not None and len(self._line) == 1
        events.append(DecodeError(reason, bytes(self._line)))
        self.errors += 1
        self._state = self._ERROR
        self._line.clear()

    def _completed(self, message: Message, events: list[object]) -> None:
        self._last = message
        events.append(message)

    def _in_error(self, byte: int, events: list[object]) -> None:
        """The error state: a newline ends the bad line (a phantom copy of the last message, see `phantoms`)."""
        if byte in _NEWLINE:
            self._state = self._START
            if self._phantom and self._last is not None:
                events.append(self._last)
        self._phantom = False

    def _fast(self, line: bytes) -> Message | None:
        raise NotImplementedError

    def _block(self, data: bytes, pos: int, events: list[object]) -> int:
        """Decode the run of well-formed messages at `pos` (the decoder is idle) at once; return where it ends."""
        return pos

    def _step(self, byte: int, events: list[object]) -> None:
        raise NotImplementedError

    def _feed(self, data: bytes) -> list[object]:
        events: list[object] = []
        memo = self._memo
        start = self._START
        pos, size = 0, len(data)
        while pos < size:
            if self._state == start and not self._line:
                nl = data.find(b"\n", pos)
                if nl < 0:
                    end = size
                else:
                    line = data[pos:nl]
                    message = memo.get(line)
                    if message is not None:
                        self._completed(message, events)
                        pos = nl + 1
                        continue
                    message = self._fast(line)
                    if message is not None:
                        if len(line) <= _MEMO_LINE:
                            if len(memo) >= _CACHE_LIMIT:
                                memo.clear()
                            memo[line] = message
                        self._completed(message, events)
                        # Traffic the memo does not know: take what follows as one block.
                        pos = self._block(data, nl + 1, events)
                        continue
                    end = nl + 1
            else:
                nl = data.find(b"\n", pos)
                end = size if nl < 0 else nl + 1
            step = self._step
            for i in range(pos, end):
                step(data[i], events)
            pos = end
        return events


class RequestDecoder(_Decoder):
    """The MMU's request automaton. `feed` returns requests and `DecodeError`s; a line that ends in error gives
    no message (the firmware completes it as an 'unknown' request and does not answer)."""

    _CODE, _VALUE, _ADDRESS, _WVALUE, _CRC = 0, 1, 2, 3, 4

    def __init__(self, *, phantoms: bool = False) -> None:
        super().__init__(phantoms=phantoms)
        self._code = ""
        self._value = 0
        self._value2 = 0
        self._crc = 0

    def feed(self, data: bytes | bytearray) -> list[RequestEvent]:
        return self._feed(bytes(data))  # type: ignore[return-value]

    def _fast(self, line: bytes) -> Request | None:
        match = _FAST_REQUEST.fullmatch(line)
        if match is not None:
            code, value, crc = match.group(1).decode(), _hex(match.group(2), 0xFF), _hex(match.group(3), 0xFF)
            if crc != request_crc(code, value):
                return None
            return REQUEST_TYPES[code](value)
        match = _FAST_WRITE.fullmatch(line)
        if match is not None:
            value, data, crc = (_hex(match.group(1), 0xFF), _hex(match.group(2), 0xFFFF),
                                _hex(match.group(3), 0xFF))
            if crc != request_crc("W", value, data):
                return None
            return Write(value, data)
        return None

    def _step(self, byte: int, events: list[object]) -> None:
        state = self._state
        if state == self._ERROR:
            self._in_error(byte, events)
            return
        if len(self._line) < _ERROR_SNIPPET:
            self._line.append(byte)
        nibble = _HEX[byte]
        if state == self._CODE:
            if byte in _REQUEST_CODE_BYTES:
                self._code = chr(byte)
                self._value = self._value2 = self._crc = 0
                self._state = self._ADDRESS if byte == 0x57 else self._VALUE
                return
            self._fail("not a request code", events)
        elif state == self._VALUE:
            if nibble >= 0:
                self._value = ((self._value << 4) | nibble) & 0xFF
            elif byte == 0x2A:
                self._state = self._CRC
            else:
                self._fail("expected a lowercase hex digit or '*'", events)
        elif state == self._ADDRESS:
            if nibble >= 0:
                self._value = ((self._value << 4) | nibble) & 0xFF
            elif byte == 0x20:
                self._state = self._WVALUE
            else:
                self._fail("expected a lowercase hex digit or ' ' after the W address", events)
        elif state == self._WVALUE:
            if nibble >= 0:
                self._value2 = ((self._value2 << 4) | nibble) & 0xFFFF
            elif byte == 0x2A:
                self._state = self._CRC
            else:
                self._fail("expected a lowercase hex digit or '*'", events)
        else:  # CRC
            if nibble >= 0:
                self._crc = ((self._crc << 4) | nibble) & 0xFF
            elif byte in _NEWLINE:
                if self._crc == request_crc(self._code, self._value, self._value2):
                    cls = REQUEST_TYPES[self._code]
                    self._completed(Write(self._value, self._value2) if cls is Write else cls(self._value), events)
                    self._state = self._CODE
                    self._line.clear()
                else:
                    self._fail("CRC mismatch", events)
            else:
                self._fail("expected a lowercase hex digit or newline in the CRC", events)


class ResponseDecoder(_Decoder):
    """The printer's response automaton: like the request one, but leading CR/LF are skipped."""

    _RCODE, _RVALUE, _PCODE, _PVALUE, _CRC = 0, 1, 2, 3, 4

    def __init__(self, *, phantoms: bool = False) -> None:
        super().__init__(phantoms=phantoms)
        self._code = ""
        self._value = 0
        self._param = ""
        self._pvalue = 0
        self._digits = False
        self._crc = 0

    def feed(self, data: bytes | bytearray) -> list[ResponseEvent]:
        return self._feed(bytes(data))  # type: ignore[return-value]

    def _fast(self, line: bytes) -> Response | None:
        match = _FAST_RESPONSE.fullmatch(line)
        if match is None:
            return None
        code_b, value_b, param_b, digits, crc_b = match.groups()
        code, param = chr(code_b[0]), chr(param_b[0])
        value = int(value_b, 16) & 0xFF if value_b else 0
        pvalue = int(digits, 16) & 0xFFFF if digits else 0
        crc = int(crc_b, 16) & 0xFF if crc_b else 0
        if crc != response_crc(code, value, param, pvalue):
            return None
        return _response(RESPONSE_TYPES[param], code, value, pvalue if digits else None)

    def _block(self, data: bytes, pos: int, events: list[object]) -> int:
        """The fields of every line at once (bytes methods over the block), then per line: two table lookups,
        one `int`, the CRC from `CRC_TABLE`, compared with the CRC's text. A line whose CRC text differs ends the
        block there; the line-by-line path then decides it (other spelling, or a real mismatch)."""
        match = _RESPONSE_BLOCK.match(data, pos)
        if match is None:
            return pos
        end = match.end()
        block = data[pos:end]
        for space_param, split in _PARAM_SPLIT:
            block = block.replace(space_param, split)
        fields = iter(block.translate(_FIELD_SEPARATORS).split(b" "))
        heads, params, table, crc_text = _response_heads(), _PARAMS, CRC_TABLE, _CRC_TEXT
        new, set_code, set_value, set_number = object.__new__, _SET_CODE, _SET_VALUE, _SET_NUMBER
        before = len(events)
        append = events.append
        number: int | None
        for head, param, digits, crc in zip(fields, fields, fields, fields, strict=False):  # + the empty tail
            code, value, state = heads[head]
            cls, param_byte = params[param]
            if digits:
                number = int(digits, 16)
                check = table[table[table[state ^ param_byte] ^ (number & 0xFF)] ^ (number >> 8)]
            else:
                number = None
                check = table[table[table[state ^ param_byte]]]
            if crc_text[check] != crc:
                done = len(events) - before
                end = pos + sum(map(len, data[pos:end].split(b"\n", done)[:done])) + done
                break
            message = new(cls)  # `_response`, inlined: this loop is the decoder's hot path
            set_code(message, code)
            set_value(message, value)
            set_number(message, number)
            append(message)
        if len(events) > before:
            self._last = events[-1]  # type: ignore[assignment]
        return end

    def _step(self, byte: int, events: list[object]) -> None:
        state = self._state
        if state == self._ERROR:
            self._in_error(byte, events)
            return
        nibble = _HEX[byte]
        if state == self._RCODE:
            if byte in _NEWLINE:
                return
            self._line.append(byte)
            if byte in _REQUEST_CODE_BYTES:
                self._code = chr(byte)
                self._value = self._pvalue = self._crc = 0
                self._state = self._RVALUE
                return
            self._fail("not a request code", events)
            return
        if len(self._line) < _ERROR_SNIPPET:
            self._line.append(byte)
        if state == self._RVALUE:
            if nibble >= 0:
                self._value = ((self._value << 4) | nibble) & 0xFF
            elif byte == 0x20:
                self._state = self._PCODE
            else:
                self._fail("expected a lowercase hex digit or ' '", events)
        elif state == self._PCODE:
            if byte in _PARAM_CODE_BYTES:
                self._param = chr(byte)
                self._pvalue = 0
                self._digits = False
                self._state = self._PVALUE
            else:
                self._fail("not a response parameter code", events)
        elif state == self._PVALUE:
            if nibble >= 0:
                self._pvalue = ((self._pvalue << 4) | nibble) & 0xFFFF
                self._digits = True
            elif byte == 0x2A:
                self._state = self._CRC
            else:
                self._fail("expected a lowercase hex digit or '*'", events)
        else:  # CRC
            if nibble >= 0:
                self._crc = ((self._crc << 4) | nibble) & 0xFF
            elif byte in _NEWLINE:
                if self._crc == response_crc(self._code, self._value, self._param, self._pvalue):
                    self._completed(_response(RESPONSE_TYPES[self._param], self._code, self._value,
                                              self._pvalue if self._digits else None), events)
                    self._state = self._RCODE
                    self._line.clear()
                else:
                    self._fail("CRC mismatch", events)
            else:
                self._fail("expected a lowercase hex digit or newline in the CRC", events)
