"""G-code moves read into arrays: the X, Y, Z, E and F words of a piece of ordinary slicer output, found and parsed
with whole-array operations instead of one line at a time.

The rules are Marlin's (see `gcodeinfo`): a word is a letter, optional blanks, then a decimal number without exponent;
`;` ends the code of a line; a letter repeated in a move is refused (`LINE_RULES`). Layouts these arrays do not
cover (indented or numbered lines, lower-case command letters, `(...)` comments, checksums, repeated letters, the
lines `LINE_RULES` refuses) are left to the line-by-line reader: `scan` says None for them.
"""

from __future__ import annotations

import functools
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

AXES = b"XYZEFIJRP"
"""The words read: the axes, the feed rate, and the centre offsets, radius and full turns of G2/G3 arcs."""
_LETTERS = AXES + bytes(sorted(set(b"ABCDEFGHIJKLMNOPQRSTUVWXYZ") - set(AXES + b"GM")))
"""Every parameter letter: `AXES`, then the others, which are only checked (a letter repeated in a move)."""
_AXIS_INDEX = np.full(256, -1, dtype=np.int8)
_AXIS_INDEX[list(_LETTERS)] = _AXIS_INDEX[list(_LETTERS.lower())] = np.arange(len(_LETTERS))
_PLAIN_AXES = 5
"""X, Y, Z, E, F: the words a piece without arcs needs (I, J, R and P are kept only where G2/G3 lines are)."""
def _byte_class(members: bytes) -> NDArray[np.bool_]:
    """A lookup table over byte values: True for each of `members`."""
    table = np.zeros(256, dtype=bool)
    table[list(members)] = True
    return table


_NOT_CODE = _byte_class(b"(*")
_DIGIT_OR_DOT = _byte_class(b"0123456789.")
_DIGIT = _byte_class(b"0123456789")
_GLUED = _byte_class(b"EeXx")
"""Letters that, right after a number, make it an exponent or a hexadecimal number to strtod (`NUMBER_FORMS`)."""
_BLANK = _byte_class(b" \t")
_WORD_END = _byte_class(b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz;\n")
"""Bytes that may follow a word's number or a command word, after blanks (the arrays leave `(` and `*` to the line
reader)."""
_MOVE_DIGIT = _byte_class(b"0123")
_ODD_FIRST = _byte_class(b" \tNngm")
"""First bytes of a line that only the line reader understands: blanks, line numbers, lower-case commands."""

VALUE = rb"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)"
"""A word's number as Marlin reads it: decimal, no exponent."""
_NUMBER = re.compile(VALUE)
_CONTROL = re.compile(rb"\n(?:G0*(92|90|91|28|4)|M0*(82|83|201|203|204|205))(?![0-9.])([^\n;]*)")
_WORD = re.compile(rb"[A-Z][ \t]*" + _NUMBER.pattern)
_SET_ONLY = re.compile(rb"[^XYZE0-9.+\- \t]")
_UNSIGNED = rb"(?>[0-9]+\.?[0-9]*|\.[0-9]+)"
"""A number without sign as `VALUE` reads it; atomic, so that `1.2` is never retried as `1` and `.2`."""
_CODE_END = rb"[A-Z;(*\n]|$"
"""What may follow a word's value, after blanks: the next word's letter or the end of the line's code."""


@dataclass(frozen=True, slots=True)
class NumberForm:
    """A word value that is not exactly one plain decimal number (`VALUE`): firmwares' number readers take it in
    different ways, so that no check of ours stands for what the printer does. Refused on G lines with the line's
    number and the word.

    `pattern` matches the value after the word's letter and blanks (case-insensitive); `examples` are whole words;
    `reading` says how firmwares part ways on it; `source` names the public description of that reading."""

    construct: str
    pattern: bytes
    examples: tuple[bytes, ...]
    reading: str
    source: str


NUMBER_FORMS: tuple[NumberForm, ...] = (
    NumberForm("a number with an exponent", _UNSIGNED.join((rb"[+-]?", rb"E")), (b"X1e3", b"Y.5E2", b"Z-1e400",
                                                                                  b"E+2e1", b"F1e9", b"X1.E2"),
               "strtod reads X1e3 as 1000 (and X1e400 as infinity) where Marlin cuts the value at the E and reads 1",
               "Marlin GCodeParser::value_float (cuts the value at E and X before strtof); C strtod(3) (exponents)"),
    NumberForm("a hexadecimal number", _UNSIGNED.join((rb"[+-]?", rb"X")), (b"X0x3E8", b"Y0X10", b"F-0x1p4"),
               "strtod reads X0x3E8 as 1000 where Marlin cuts the value at the x and reads 0",
               "Marlin GCodeParser::value_float (cuts at E and X); C strtod(3) (0x hexadecimal floats)"),
    NumberForm("NaN or infinity", rb"[+-]?(?:NAN|INF)", (b"Xnan", b"Y-INF", b"Zinfinity", b"X NaN", b"E+inf"),
               "strtod reads a NaN or an infinity (a move to infinity) where Marlin finds no number",
               "C strtod(3) (NAN, INF); Marlin GCodeParser::valid_float (a number starts [-+]?.?[0-9])"),
    NumberForm("two signs", rb"[+-][ \t]*[+-]", (b"X--1000", b"X+-1000", b"X-+1000", b"E--5", b"Y- -5"),
               "Marlin finds no number and leaves the axis alone, a reader that takes signs one at a time reads "
               "X--1000 as 1000 or -1000",
               "Marlin GCodeParser::valid_float ([-+]?.?[0-9]: one sign at most); RepRap wiki G-code, 'Fields'"),
    NumberForm("a sign and a dot without digits", rb"[+-]\.(?![0-9])", (b"X-.", b"Y+.", b"Z-. E1"),
               "Marlin finds no number, strtod-style readers take it as 0",
               "Marlin GCodeParser::valid_float ([-+]?.?[0-9]: a digit is needed); C strtod(3) (no conversion)"),
    NumberForm("a sign without digits", rb"[+-](?![ \t]*[0-9.+-])", (b"X-", b"Y+", b"E-;", b"X-Y10"),
               "Marlin finds no number and leaves the axis alone, readers that take a missing number as 0 move to 0",
               "Marlin GCodeParser::valid_float ([-+]?.?[0-9]); Marlin 1.0 code_value (strtod of no number is 0)"),
    NumberForm("a dot without digits", rb"\.(?![0-9])", (b"X.", b"Y. E1", b"E.;"),
               "Marlin finds no number and leaves the axis alone, readers that take a missing number as 0 move to 0",
               "Marlin GCodeParser::valid_signless (.?[0-9]: a dot needs a digit after it); C strtod(3)"),
    NumberForm("a sign after the number", _UNSIGNED.join((rb"[+-]?", rb"[+-]")), (b"X1-", b"Y10+", b"X1-5",
                                                                                 b"E2+3"),
               "Marlin skips the signs and digits after the number (X1-5 is 1), a reader that adds up signed "
               "pieces reads -4",
               "Marlin GCodeParser::parse (skips DECIMAL_SIGNED characters after a value); C strtod(3)"),
    NumberForm("two dots", _UNSIGNED.join((rb"[+-]?", rb"\.")), (b"X1.2.3", b"Y1..", b"E.5.5"),
               "strtod and Marlin stop at the second dot (1.2), other readers refuse the word or take 1.23",
               "C strtod(3) (one radix character); Marlin GCodeParser::parse (skips the rest of a value)"),
    NumberForm("a number split by blanks", _UNSIGNED.join((rb"(?:[+-]|[+-]?", rb")[ \t]+[0-9.+-]")),
               (b"X1 0", b"X- 5", b"Y1 .5", b"X1 -2", b"E+ 1"),
               "Marlin reads X1 0 as 1 (a blank ends a value), Grbl drops every blank first and reads 10",
               "Marlin GCodeParser::parse (a blank ends a value); Grbl gcode.c (blanks are removed before parsing)"),
    NumberForm("a character no number holds",
               rb"(?:[+-]?" + _UNSIGNED + rb")?[ \t]*[^A-Z0-9.+\-;(*\n \t]",
               (b"X10,5", "X\u22121000".encode(), "X\uff11\uff10".encode(), b"X#1", b"X1_000",
                b"X{1}", "X1\u00b75".encode()),
               "Marlin reads ASCII digits only (X\u22121000 is no number, X10,5 is 10), while Python's float() "
               "takes other scripts' digits and a locale-aware reader takes the comma as a decimal point",
               "Marlin macros.h NUMERIC ('0'-'9' only); Python float() (Unicode decimal digits, _ separators); "
               "RepRap wiki G-code, 'Fields' (a number in ASCII digits)"),
)
"""The malformed word values, each refused on any G line (in the code, not in a comment). The first row that matches
names the form."""
EMPTY_VALUE = NumberForm(
    "a letter without a value on a move or position command", rb"", (b"X", b"F", b"Z X1", b"E;"),
    "Marlin leaves the axis alone, readers of the Sprinter line (Marlin 1.0 code_value) take no number as 0 "
    "and move to 0", "Marlin GCodeParser::seenval (no value: not used by G0-G3/G92); Marlin 1.0 Marlin_main.cpp "
    "get_coordinates (code_value is strtod of what follows)")
"""A bare letter on G0-G3 and G92 (elsewhere, as in `G28 X Y`, a bare letter is an ordinary flag)."""
MALFORMED = re.compile(rb"[A-Z][ \t]*(?:" + b"|".join(b"(" + form.pattern + b")" for form in NUMBER_FORMS) + b")",
                       re.IGNORECASE)
"""A word whose value is one of `NUMBER_FORMS` (`lastindex` - 1 is its row)."""
EMPTY_ON_MOVE = re.compile(
    rb"^[ \t]*(?:N[0-9]+[ \t]*)?G[ \t]*0*(?:[0-3]|92)(?![0-9.])[^;(*\n]*?([A-Z])(?=[ \t]*(?:" + _CODE_END + rb"))",
    re.IGNORECASE | re.MULTILINE)
"""The first bare letter on a move or position line (`EMPTY_VALUE`; group 1 is the letter)."""
_FULL_WORD = rb"[ \t]*[A-Z][ \t]*[+-]?" + _UNSIGNED + rb"(?![EX])"
_ANY_WORD = rb"[ \t]*[A-Z][ \t]*(?:[+-]?" + _UNSIGNED + rb"(?![EX]))?"
_PARENS = rb"|[ \t]*\([^)\n]*\)"
_MOVE = rb"(?:[0-3]|92)(?![0-9])"
SUSPECT_LINE = re.compile(
    rb"^(?![ \t]*(?:N[0-9]+[ \t]*)?G[ \t]*0*(?:" + _MOVE + rb"(?:\.[0-9]*)?(?:" + _FULL_WORD + _PARENS + rb")*+"
    rb"|(?!" + _MOVE + rb")[0-9]+(?:\.[0-9]*)?(?:" + _ANY_WORD + _PARENS + rb")*+)[ \t]*(?:[;(*\n]|$))"
    rb"[ \t]*(?:N[0-9]+[ \t]*)?G[ \t]*[0-9]", re.IGNORECASE | re.MULTILINE)
"""The start of a G line whose code is not plain words (a letter, blanks, one plain decimal number, no E or X
glued to it; bare letters only off G0-G3/G92): each valid line is read once, so this finds the few others fast.
`malformed_word` says which word of such a line is at fault."""


_COMMAND_WORD = re.compile(rb"[ \t]*(?:N[0-9]+[ \t]*)?G[ \t]*[0-9]+(?:\.[0-9]*)?", re.IGNORECASE)
_JUNK_FIRST = re.compile(rb"[ \t]*([^A-Z \t])", re.IGNORECASE)


def malformed_word(line: bytes) -> tuple[bytes, NumberForm] | None:
    """The first word of a G command line (without its line break) whose value is one of `NUMBER_FORMS`, or a bare
    letter on G0-G3/G92 (`EMPTY_VALUE`), with its form; None when its code holds none or it is no G command (`G`
    without a number). Comments (`;`, `(...)`) and a checksum are not code."""
    code = line.partition(b";")[0].partition(b"*")[0]
    if b"(" in code:
        code = re.sub(rb"\([^)]*\)?", lambda found: b" " * len(found.group(0)), code)
    command = _COMMAND_WORD.match(code)
    if command is None:
        return None  # no G command (`G` without a number)
    found = MALFORMED.search(code, command.end())
    if found is None or found.start() > command.end():
        junk = _JUNK_FIRST.match(code, command.end())
        if junk is not None:  # a value with no letter before it
            return code[junk.start(1):].split()[0], NUMBER_FORMS[-1]
    bare = EMPTY_ON_MOVE.match(code + b"\n")
    if bare is not None and (found is None or bare.start(1) < found.start()):
        return code[bare.start(1):bare.end(1)], EMPTY_VALUE
    if found is None:
        return None
    form = NUMBER_FORMS[(found.lastindex or 1) - 1]
    end = found.end()
    while end < len(code) and code[end:end + 1] not in b" \t":
        end += 1  # the rest of the value, for the message
    return code[found.start():end].strip(), form


@dataclass(frozen=True, slots=True)
class LineRule:
    """A kind of G-code line that firmwares read differently, so that no check of ours stands for what the printer
    does: refused with the line's number, what it holds (`reading`) and what to do (`advice`)."""

    construct: str
    example: bytes
    reading: str
    advice: str
    source: str


LINE_RULES: tuple[LineRule, ...] = (
    LineRule("a number with an exponent, or no number (X1e3, X nan)", b"G1 X1e3 Y10 E5",
             "is a number with an exponent or no number at all, which printers read differently (a move to "
             "infinity)", "write it as plain decimals",
             "Marlin GCodeParser::value_float (strtod reads exponents); RepRap wiki G-code, 'Fields' (plain numbers)"),
    LineRule("a letter given twice in one move", b"G1 X10 X1000 Y10 E5",
             "gives a letter twice: Marlin's fast parser takes the last one, other readers the first",
             "write each letter once",
             "Marlin src/gcode/parser.cpp (FASTER_GCODE_PARSER: a repeated letter overwrites the earlier one)"),
    LineRule("a second command word on a line", b"G1 X10 G1 X1000 Y10 E5",
             "holds a second command word: RepRapFirmware runs both commands, Marlin reads the second as a parameter",
             "put each command on its own line",
             "RepRap wiki G-code ('a line holds one command'); RepRapFirmware GCodes (several commands on one line)"),
    LineRule("a command subcode on a move, position or unit command (G1.0)", b"G1.0 X1000 Y10 E5",
             "has a subcode: a firmware that ignores subcodes runs the command itself, others refuse the line",
             "write the command without `.n`",
             "RepRap wiki G-code, 'Codes with subcodes'; Marlin GCodeParser (USE_GCODE_SUBCODES is optional)"),
    LineRule("a line break other than LF or CR in the code of a line (form feed, vertical tab, U+0085, U+2028, "
             "U+2029; a comment is any text)",
             b"G1 X10\fG1 X1000 Y10 E5",
             "holds a form feed, vertical tab, U+0085, U+2028 or U+2029, which some readers take as a line break",
             "remove it (end lines with LF or CR LF only)",
             "Unicode Standard Annex #14 (mandatory breaks) as Python's str.splitlines reads them; Marlin "
             "GCodeQueue ends a line only at LF or CR"),
    LineRule("inch units (G20)", b"G20\nG1 X50 Y10 E5",
             "sets inch units: a firmware with INCH_MODE_SUPPORT moves 25.4 times as far, others stay in mm",
             "slice in millimetres (G21)", "Marlin G20 Inch Units (marlinfw.org/docs/gcode/G020.html)"),
    LineRule("an arc without a centre (R0, I0 J0, an R arc that ends where it starts)", b"G2 X20 Y10 R0 E5",
             "is an arc whose centre offset is zero: Marlin refuses it ('G2/G3 bad parameters') and does not move, "
             "while a reader that runs it as a straight line extrudes along it",
             "give the centre with I and J, or a radius R other than 0 and an end point away from the start",
             "Marlin gcode/motion/G2_G3.cpp (arc_offset of zero: STR_ERR_ARC_ARGS, no move); Marlin G2-G3 "
             "(marlinfw.org/docs/gcode/G002-G003.html)"),
    LineRule("an arc's full-turn count P that is not a whole number from 0 to 100", b"G2 X10 Y10 I5 J0 P1000000000 E5",
             "has a full-turn count Marlin does not run as written: ARC_P_CIRCLES takes 0 to 100 turns and reports "
             "'G2/G3 bad parameters' for others, firmwares without it ignore P",
             "write P as a whole number of turns from 0 to 100",
             "Marlin gcode/motion/G2_G3.cpp (ARC_P_CIRCLES: P outside 0-100 is STR_ERR_ARC_ARGS); Marlin G2-G3 "
             "(marlinfw.org/docs/gcode/G002-G003.html, P: full circles)"),
)
"""Lines refused because printers read them differently (the first row stands for `NUMBER_FORMS`; the others are
found by the move analysis, `gcodeinfo.MoveAnalyzer`, which raises `Ambiguous`)."""
EXPONENT, REPEATED, SECOND_COMMAND, SUBCODE, SEPARATOR, INCHES, CENTRELESS, TURNS = LINE_RULES
SEPARATORS = (b"\x0b", b"\x0c", b"\xc2\x85", b"\xe2\x80\xa8", b"\xe2\x80\xa9")
"""Line breaks some readers see inside what a firmware reads as one line (UTF-8 of U+0085, U+2028, U+2029)."""
TEXT_COMMANDS = frozenset({b"M0", b"M1", b"M16", b"M23", b"M28", b"M30", b"M32", b"M33", b"M117", b"M118", b"M928"})
"""Commands whose parameter is text (a message or a file name), where a G or M followed by a number is only text:
Marlin's G-code index (M0/M1 prompt, M16 printer check, M23/M28/M30/M32/M33 SD file names, M117 LCD message,
M118 serial print, M928 log file). Any other line holding a second command word is refused (`LINE_RULES`)."""
SECOND_COMMAND_WORD = rb"[GM][ \t]*[-+.0-9]"
"""A command word in the parameters of another command (`LINE_RULES`' second command word)."""
_SECOND_COMMAND_LINE = re.compile(
    rb"\n(?!M0*(?:" + b"|".join(c[1:] for c in sorted(TEXT_COMMANDS)) + rb")(?![0-9.]))[GM][^\n;]*?"
    + SECOND_COMMAND_WORD, re.IGNORECASE)
"""A command line, not a text command, with a second command word in its code (`TEXT_COMMANDS`)."""
_REFUSED_COMMAND = re.compile(rb"\nG0*(?:(?:[0-3]|92|2[01])\.|20(?![0-9.]))")
"""A G-code command line the arrays leave to the line reader to refuse: a subcode or G20."""
_NEWLINE, _SEMICOLON = 4, 5
_SCAN_FLAGS = bytes(1 if _AXIS_INDEX[byte] >= 0 else 2 if byte in b"GMgm" else 3 if byte in b"\x0b\x0c\x85\xa8\xa9"
                    else _NEWLINE if byte == 10 else _SEMICOLON if byte == 59 else 0 for byte in range(256))
"""bytes.translate table: 1 for a parameter letter, 2 for a command letter, 3 for a byte that may be (the end of)
one of SEPARATORS, `_NEWLINE` for LF, `_SEMICOLON` for `;`, 0 for anything else."""


class Ambiguous(Exception):
    """A line `LINE_RULES` refuses, at `offset` (the line's start) in the text the analysis was given."""

    def __init__(self, rule: LineRule, offset: int = 0) -> None:
        super().__init__(rule.construct)
        self.rule = rule
        self.offset = offset


def line_count(text: bytes) -> int:
    """How many LF bytes `text` holds (numpy counts them about 20 times as fast as `bytes.count`)."""
    return int(np.count_nonzero(np.frombuffer(text, dtype=np.uint8) == 10))


PAD = 32
"""Zero bytes after the text, so reads of a number's 16 bytes never run past the buffer."""

# Eight ASCII digits in one 64-bit word (first character in the lowest byte) are read with three multiply-add steps
# ("SWAR"), and the digits before a non-digit are counted from a mask of non-digit bytes.
_U = np.uint64
_ZEROS = _U(0x3030303030303030)
_LOW7 = _U(0x7F7F7F7F7F7F7F7F)
_ABOVE_9 = _U(0x7676767676767676)
_HIGH = _U(0x8080808080808080)
_PAIRS = (_U(10), _U(8), _U(0x00FF00FF00FF00FF))
_QUADS = (_U(100), _U(16), _U(0x0000FFFF0000FFFF))
_OCTETS = (_U(10000), _U(32), _U(0x00000000FFFFFFFF))
_SCALE = 10**8


@functools.cache
def reuse_freed_memory() -> None:
    """Allocate and free one 16 MiB block, once per process.

    glibc's malloc then raises its mmap threshold to that size and its trim threshold to twice it (the "dynamic
    mmap threshold" of mallopt(3)), so the megabyte-sized temporary arrays of each piece reuse the heap instead of
    being mapped, page-faulted in and returned afresh for every piece, which took as long as the arithmetic. Other
    allocators are unaffected.
    """
    np.empty(16 << 20, dtype=np.uint8)


def _digits_value(x: NDArray[np.uint64]) -> NDArray[np.uint64]:
    """The number that eight digit values (0-9, most significant in the lowest byte) spell; `x` is overwritten."""
    for factor, shift, mask in (_PAIRS, _QUADS, _OCTETS):
        low = x >> shift
        x *= factor
        x += low
        x &= mask
    return x


def _leading_digits(x: NDArray[np.uint64]) -> NDArray[np.uint8]:
    """How many of the eight bytes (XORed with '0') are digits before the first non-digit (8 if all are)."""
    non_digit = x & _LOW7
    non_digit += _ABOVE_9
    non_digit |= x
    non_digit &= _HIGH
    lowest = _U(0) - non_digit
    lowest &= non_digit
    lowest -= _U(1)
    counted: NDArray[np.uint8] = np.bitwise_count(lowest)
    counted >>= np.uint8(3)
    return counted


def _eight_bytes(data: NDArray[np.uint8], at: NDArray[np.intp]) -> tuple[NDArray[np.uint64], NDArray[np.uint64]]:
    """The 8 bytes at each offset `at` of `data` and the 8 after them, as little-endian numbers (the last 24 bytes
    of `data` must be PAD), joined from aligned words: gathering aligned words is several times as fast."""
    aligned = np.frombuffer(data, dtype="<u8", count=len(data) // 8)
    word = at >> 3
    first = aligned.take(word)
    word += 1
    second = aligned.take(word)
    word += 1
    third = aligned.take(word)
    shift = ((at & 7) << 3).view(np.uint64)  # offsets are not negative: the same bits
    rest = _U(64) - shift  # numpy shifts a 64-bit number by 64 to 0
    first >>= shift
    first |= second << rest
    second >>= shift
    second |= third << rest
    return first, second


def parse_numbers(padded: bytes, data: NDArray[np.uint8], at: NDArray[np.intp]) -> NDArray[np.float64]:
    """The numbers starting at offsets `at` of some text followed by PAD zero bytes (`padded`, and `data` viewing
    it), as float() reads them; NaN where no number starts (`parse_words`)."""
    return parse_words(padded, data, at)[0]


def parse_words(padded: bytes, data: NDArray[np.uint8], at: NDArray[np.intp], first: NDArray[np.uint8] | None = None
                ) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """(the numbers starting at offsets `at` of some text followed by PAD zero bytes, as float() reads them, NaN
    where no number starts; how many bytes each number spans, sign included). `first`: the bytes at `at`, when the
    caller has them.

    Up to 7 integer and 8 fraction digits make an exact integer over 10^8, which one division rounds as a float
    parser does; longer numbers go to float() itself.
    """
    sign = data.take(at) if first is None else first
    negative = sign == ord("-")
    low, high = _eight_bytes(data, at + (negative | (sign == ord("+"))))  # the digits after any sign
    low ^= _ZEROS
    high ^= _ZEROS
    whole_digits = _leading_digits(low)  # counts and shifts in bytes: at most 8 digits, 72 bits
    whole_bits = whole_digits << np.uint8(3)
    dotted = (low >> whole_bits) & _U(0xFF) == _U(ord(".") ^ 0x30)
    after_dot = whole_bits + np.uint8(8)
    fraction = np.bitwise_or(low >> after_dot, high << (_U(64) - after_dot))
    fraction_digits = _leading_digits(fraction)
    fraction_digits *= dotted
    fraction &= (_U(1) << (fraction_digits << np.uint8(3))) - _U(1)
    mantissa = _digits_value(low << (np.uint8(64) - whole_bits)) * _U(_SCALE) + _digits_value(fraction)
    parsed: NDArray[np.float64] = mantissa.astype(np.float64) / _SCALE
    np.negative(parsed, out=parsed, where=negative)
    parsed[(whole_digits == 0) & (fraction_digits == 0)] = np.nan
    signed = (negative | (sign == ord("+"))).astype(np.intp)
    spans = signed + whole_digits + dotted + fraction_digits
    for i in np.flatnonzero((whole_digits == 8) | (fraction_digits == 8)).tolist():  # long: the float parser's
        found = _NUMBER.match(padded, int(at[i]))
        parsed[i] = float(found.group(0)) if found else math.nan
        spans[i] = found.end() - found.start() if found else 0
    return parsed, spans


@dataclass(frozen=True, slots=True)
class Words:
    """One axis's words in a piece, in order: the line each is on, its value, whether that line is a G92."""

    lines: NDArray[np.intp]
    values: NDArray[np.float64]
    sets: NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class Scan:
    """A piece read into arrays: the words of each of `AXES` on move (G0-G3) and plain G92 lines, and the
    other commands that change the analysis (line, command, upper-cased parameters), in order."""

    axes: tuple[Words, ...]
    controls: list[tuple[int, bytes, bytes]]
    arcs: NDArray[np.int8]
    """Per line of the piece: 2 for a G2 (clockwise arc), 3 for a G3, else 0."""
    g0_at: NDArray[np.intp] | None = None
    """Offsets in the padded piece of the `0` of each G0 (or the second of each G00) command word, which a printer
    that knows no G0 is given as G1."""
    odd_at: int | None = None
    """Where (offset in the padded piece) the first G line starts that may hold a word of `NUMBER_FORMS` in
    its code: a letter without a number, an E or X right after a number, more after a number or the command word
    than blanks before the next letter, or a `SUSPECT_LINE` among the other G lines (None when no line may)."""


BLANK_ROUNDS = 8
"""Blanks skipped a byte at a time for all offsets at once; the few offsets on longer runs are then each skipped by
one regular-expression match, so a run of a million blanks costs one scan of it, not a million array rounds."""
_BLANKS = re.compile(rb"[ \t]*")


def after_blanks(data: NDArray[np.uint8], at: NDArray[np.intp]) -> NDArray[np.uint8]:
    """Move each offset `at` past the blanks (space, tab) there, in place, and return the bytes there now: each
    round only the offsets still on a blank move, and after BLANK_ROUNDS the rest are skipped one by one."""
    first = data.take(at)
    moving = np.flatnonzero(_BLANK.take(first))
    if not len(moving):
        return first
    for _ in range(BLANK_ROUNDS):
        at[moving] += 1
        moving = moving[_BLANK.take(data.take(at.take(moving)))]
        if not len(moving):
            return data.take(at)
    text = data.data  # the bytes themselves, not a copy
    for index in moving.tolist():
        at[index] = _BLANKS.match(text, int(at[index])).end()  # type: ignore[union-attr]  # `*` always matches
    return data.take(at)


def _ends_word(data: NDArray[np.uint8], after: NDArray[np.intp],
               first: NDArray[np.uint8] | None = None) -> NDArray[np.bool_]:
    """Whether blanks at most come between each offset `after` and the next word or the code's end (`_WORD_END`);
    `first`: the bytes at `after`, when the caller has them. One blank or none is the rule in slicers' output, so
    only the other offsets are walked past their blanks."""
    if first is None:
        first = data.take(after)
    ends = _WORD_END.take(first)
    ends |= _BLANK.take(first) & _WORD_END.take(data.take(after + 1))
    rest = np.flatnonzero(~ends)
    if len(rest):
        further = after.take(rest)
        ends[rest] = _WORD_END.take(after_blanks(data, further))
    return ends


def _tiled(data: NDArray[np.uint8], letters: NDArray[np.intp], spans: NDArray[np.intp], known: NDArray[np.bool_],
           starts: NDArray[np.intp], ends: NDArray[np.intp],
           command: tuple[NDArray[np.uint8], NDArray[np.uint8], NDArray[np.uint8]]) -> bool:
    """Whether the code of each line (from `starts` to `ends`) is its command word (G and up to three digits, whose
    bytes after the G are `command`) followed by words, each one blank, its letter (offsets `letters`) and a number
    of `spans` bytes, and nothing else: then no word holds a form of `NUMBER_FORMS`, which the word-by-word checks
    would look for. The layout slicers write, checked by counting: the blank-letter-number runs cannot overlap (a
    number is only a sign, digits and a dot), so when their lengths and the command words' add up to the code's,
    they cover it and no byte is left over."""
    if not known.all() or not _BLANK.take(data.take(letters - 1)).all():
        return False
    first, second, third = (_DIGIT.take(part) for part in command)
    second &= first
    third &= second
    command_bytes = len(starts) + np.count_nonzero(first) + np.count_nonzero(second) + np.count_nonzero(third)
    code_bytes = int(np.sum(ends - starts))
    return bool(int(np.sum(spans)) + 2 * len(letters) + command_bytes == code_bytes)


@dataclass(frozen=True)
class _Other:
    """What a command line other than a move holds: whether it is `SUSPECT_LINE`, and the command the analysis
    follows (`code`, upper-cased `params`; None for one it ignores), or whether it is a G92 that only sets
    positions (`sets`, read as a row of words)."""

    suspect: bool
    code: bytes | None
    params: bytes
    sets: bool


def _other(line: bytes) -> _Other | None:
    """Read one command line other than a move, from its newline to the next (both included); None when the line
    reader refuses it (a subcode, G20, a second command word)."""
    if _REFUSED_COMMAND.match(line) or _SECOND_COMMAND_LINE.match(line):
        return None
    suspect = line[1:2] == b"G" and SUSPECT_LINE.match(line, 1) is not None
    found = _CONTROL.match(line)
    if found is None:
        return _Other(suspect, None, b"", False)
    code = b"G" + found.group(1) if found.group(1) else b"M" + found.group(2)
    params = found.group(3).upper()
    sets = code == b"G92" and bool(_WORD.search(params)) and not _SET_ONLY.search(params)
    return _Other(suspect, code, params, sets)


def scan(padded: bytes) -> Scan | None:
    """The words of a piece of G-code (which starts with a newline and ends its last line) followed by PAD zero
    bytes, or None for a layout only the line-by-line reader handles."""
    size = len(padded) - PAD
    data = np.frombuffer(padded, dtype=np.uint8)
    text = data[:size]
    flags = np.frombuffer(padded.translate(_SCAN_FLAGS), dtype=np.uint8)
    where = np.flatnonzero(flags != 0)  # numpy finds the True of a bool array several times faster than nonzero bytes
    kind = flags.take(where)
    is_newline = kind == _NEWLINE
    newlines = where.take(np.flatnonzero(is_newline))
    starts = newlines[:-1] + 1
    if not len(starts):
        return Scan(tuple(_NO_WORDS for _ in AXES), [], np.zeros(0, dtype=np.int8))
    # the line of each flagged byte before the last newline (the last flagged byte)
    where, kind, line_of = where[:-1], kind[:-1], np.cumsum(is_newline[:-1]) - 1
    if (kind == 3).any() and any(separator in padded for separator in SEPARATORS):
        return None  # the line reader refuses it (in the code of a line) or reads the comment
    c0, c1, c2, c3 = (data.take(starts + i) for i in range(4))
    command = (c0 == ord("G")) | (c0 == ord("M"))
    if (_ODD_FIRST.take(c0) | (command & (
            (c1 == 32) | (c1 == 9) | ((c1 == 48) & (c2 == 48) & (c3 - np.uint8(48) <= 9))))).any():
        return None  # blanks, a number or lower case before the command, blanks inside it, or `G001`
    is_move = (c0 == ord("G")) & (
        (_MOVE_DIGIT.take(c1) & ~_DIGIT_OR_DOT.take(c2))
        | ((c1 == ord("0")) & _MOVE_DIGIT.take(c2) & ~_DIGIT_OR_DOT.take(c3))
    )
    g0 = (c0 == ord("G")) & (c1 == ord("0"))
    g0_at = np.concatenate((starts[g0 & ~_DIGIT_OR_DOT.take(c2)] + 1,
                            starts[g0 & (c2 == ord("0")) & ~_DIGIT_OR_DOT.take(c3)] + 2))
    digit = np.where(c1 == ord("0"), c2, c1)
    arcs = np.where(is_move & ((digit == ord("2")) | (digit == ord("3"))), digit - ord("0"), 0).astype(np.int8)
    controls: list[tuple[int, bytes, bytes]] = []
    is_set = np.zeros(len(starts), dtype=bool)
    suspect = len(starts)
    others = np.flatnonzero(command & ~is_move)  # the other commands: each distinct line is read once
    distinct: dict[bytes, _Other | None] = {}
    for line, begin, end in zip(others.tolist(), newlines.take(others).tolist(),
                                newlines.take(others + 1).tolist(), strict=True):
        text_of = padded[begin:end + 1]
        if text_of in distinct:
            other = distinct[text_of]
        else:
            other = distinct[text_of] = _other(text_of)
        if other is None:
            return None  # the line reader refuses it
        if line < suspect and other.suspect:
            suspect = line
        if other.code is None:
            continue
        if other.sets:
            is_set[line] = True
        else:
            controls.append((line, other.code, other.params))
    is_row = is_move | is_set
    code_end = newlines[1:]
    inline_comments = False  # a `;` after the code of a move (comment lines are no moves)
    if b";" in padded:
        is_semi = kind == _SEMICOLON
        semi_at = np.flatnonzero(is_semi)
        semis, semi_lines = where.take(semi_at), line_of.take(semi_at)
        first = np.diff(semi_lines, prepend=-1) != 0  # the first `;` of each line ends its code
        inline_comments = bool(is_row.take(semi_lines).any())
        code_end = code_end.copy()
        code_end[semi_lines[first]] = semis[first]
    if b"(" in padded or b"*" in padded:
        odd = np.flatnonzero(_NOT_CODE[text])
        odd_line = np.searchsorted(newlines, odd) - 1
        if (is_row[odd_line] & (odd < code_end[odd_line])).any():  # a comment in parentheses or a checksum
            return None
    read = len(AXES) if arcs.any() else _PLAIN_AXES
    # I, J, R and P words (and the letters no analysis reads) are found and checked everywhere, kept only where arcs are
    keep = is_row.take(line_of)
    if inline_comments:
        keep &= where < code_end.take(line_of)
    if np.count_nonzero(keep & (kind == 2)) > np.count_nonzero(is_row):  # each of these lines starts with a G
        return None  # a second command word in a move: the line reader refuses it
    keep &= kind == 1
    kept = np.flatnonzero(keep)
    where, line_of = where.take(kept), line_of.take(kept)
    at = where + 1
    first = after_blanks(data, at)  # blanks between a letter and its number
    numbers, spans = parse_words(padded, data, at, first)
    axis = _AXIS_INDEX.take(data.take(where))
    known = ~np.isnan(numbers)
    rows = np.flatnonzero(is_row)
    if not _tiled(data, where, spans, known, starts.take(rows), code_end.take(rows),
                  (c1.take(rows), c2.take(rows), c3.take(rows))):
        after = at + spans
        following = data.take(after)
        malformed = _GLUED.take(following)  # an exponent or a hexadecimal number
        malformed |= ~_ends_word(data, after, following)  # more than blanks between the number and the next word
        malformed |= ~known  # bare letters are not words (and may be a NaN or an infinity)
        command_end = starts.take(rows) + 1
        while (digits := _DIGIT.take(data.take(command_end))).any():
            command_end += digits
        odd_lines = [line_of[malformed][:1], rows[~_ends_word(data, command_end)][:1]]  # or more after the command word
        if any(len(first_odd) for first_odd in odd_lines):
            suspect = min(suspect, *(int(first_odd[0]) for first_odd in odd_lines if len(first_odd)))
    if not known.all():
        axis, line_of, numbers, where = axis[known], line_of[known], numbers[known], where[known]
    unread = np.flatnonzero(axis >= read)
    if len(unread):  # letters not kept (rare on moves) are only checked: the line reader refuses a repeated one
        named = line_of[unread] * len(_LETTERS) + axis[unread]
        if len(np.unique(named)) < len(named):
            return None
    axes = []
    for k in range(len(AXES)):
        if k >= read:
            axes.append(_NO_WORDS)
            continue
        picked = np.flatnonzero(axis == k)
        lines = line_of.take(picked)
        if (lines[1:] == lines[:-1]).any():
            return None  # a letter repeats within a line
        axes.append(Words(lines, numbers.take(picked), is_set.take(lines)))
    if suspect < len(starts) and arcs.any():
        return None  # the line reader refuses an arc Marlin refuses after any malformed number in that line
    return Scan(tuple(axes), controls, arcs, g0_at, int(newlines[suspect]) + 1 if suspect < len(starts) else None)


_NO_WORDS = Words(np.zeros(0, dtype=np.intp), np.zeros(0), np.zeros(0, dtype=bool))

PIECE = 1 << 20
"""Bytes read into arrays at once: the per-word arrays of a piece this size stay in the CPU's cache."""


def scanned_pieces(chunk: bytes) -> Iterator[tuple[int, int, Scan | None]]:
    """The pieces of whole lines (about PIECE bytes each) of `chunk`, which starts at a line start, each as
    (its start offset, its end offset, `scan` of it: None for a layout only the line-by-line reader handles). The
    last line of `chunk` may lack its newline."""
    view = memoryview(chunk)
    start = 0
    while start < len(chunk):
        end = chunk.find(b"\n", start + PIECE) + 1 or len(chunk)
        ended = b"" if chunk[end - 1] == 10 else b"\n"
        yield start, end, scan(b"".join((b"\n", view[start:end], ended, bytes(PAD))))
        start = end

