"""Error words as the printer shows them: every 16-bit word against the reference's rules, titles, choices, text."""

from __future__ import annotations

import pathlib

import pytest

from fabwire.mmu.errors import RESET, MMUError, describe_error, format_error, printer_code

DATA = pathlib.Path(__file__).with_name("data") / "printer_codes.txt"

# Reference §4.2: words the printer recognises as a whole.
EXACT = {
    0x8001: "04101", 0x8002: "04102", 0x8003: "04103", 0x8004: "04104", 0x8005: "04501", 0x8006: "04502",
    0x8047: "04105", 0x804B: "04105", 0x8087: "04115", 0x808B: "04116", 0x8107: "04125", 0x810B: "04126",
    0x8008: "04506", 0x8009: "04106", 0x800A: "04107", 0x800C: "04507", 0x800D: "04306", 0x8029: "04508",
    0x802A: "04108", 0x802B: "04503", 0x802C: "04504", 0x802D: "04402", 0x802E: "04401", 0x802F: "04505",
}
# Reference §4.2 rows for driver words: flag → printer code per axis (pulley, selector, idler), in the printer's
# order of preference.
DRIVER_ROWS = [
    (0x8200, ("04301", "04311", "04321")),
    (0x8400, ("04302", "04312", "04322")),
    (0x8800, ("04303", "04313", "04323")),
    (0x9000, ("04304", "04314", "04324")),
    (0xA000, ("04201", "04211", "04221")),
    (0xC000, ("04202", "04212", "04222")),
]
SELFTEST = ("04305", "04315", "04325")


def expected_code(word: int) -> str:
    if word in EXACT:
        return EXACT[word]
    axes = [i for i, bit in enumerate((0x40, 0x80, 0x100)) if word & bit]
    if not axes:
        return "04505"
    axis = axes[0]
    if word & 0xC200 == 0xC200:
        return SELFTEST[axis]
    for flag, row in DRIVER_ROWS:
        if word & flag == flag:
            return row[axis]
    return "04505"


def test_every_16_bit_word_gets_the_printers_code() -> None:
    wrong = [(hex(w), printer_code(w), expected_code(w)) for w in range(0x10000) if printer_code(w) != expected_code(w)]
    assert wrong == []


def test_every_word_describes_itself_in_one_line() -> None:
    for word in range(0x10000):
        text = format_error(word)
        assert text.startswith(printer_code(word) + " ")
        assert text.endswith(f"(0x{word:04X})")
        assert "\n" not in text


@pytest.mark.parametrize("line", [ln for ln in DATA.read_text().splitlines() if ln and not ln.startswith("#")])
def test_captured_words(line: str) -> None:
    word, code, title = line.split("|")
    info = describe_error(int(word, 16))
    assert (info.printer_code, info.title) == (code, title)
    assert format_error(int(word, 16)) == f"{code} {title} (0x{int(word, 16):04X})"


def test_one_text_form_printer_code_first() -> None:
    assert format_error(0x8001) == "04101 FINDA DIDN'T TRIGGER (0x8001)"
    error = MMUError(0x8087, command="T1")
    assert str(error) == ("04115 SELECTOR CANNOT HOME (0x8087) during T1 — selector cannot home; "
                          "check nothing blocks the selector, then Retry")
    assert error.code == "04115 SELECTOR CANNOT HOME (0x8087)"
    assert error.exit_code == 7
    assert str(MMUError(0x802C, detail="MMU firmware 3.0.2")) == (
        "04504 MMU FW UPDATE NEEDED (0x802C): MMU firmware 3.0.2 — MMU firmware version not supported; "
        "update the MMU firmware")
    assert describe_error(0x802E).explained(detail="link failed (no answer)") == (
        "04401 MMU NOT RESPONDING (0x802E): link failed (no answer) — the MMU does not answer; "
        "check the cable and the MMU's power, then reset the MMU")


def test_combined_driver_words_name_every_flag_and_axis() -> None:
    info = describe_error(0x8000 | 0x0400 | 0x1000 | 0x0100)
    assert info.name == "TMC_RESET|TMC_SHORT_TO_GROUND_IDLER"
    assert info.meaning == "idler driver: driver reset, short to ground"
    assert describe_error(0x84C0).meaning == "pulley and selector driver: driver reset"
    assert describe_error(0x1234).name == "ERROR_1234"


@pytest.mark.parametrize(("word", "choices", "retry"), [
    (0x8001, [("Retry", 1)], True),
    (0x8087, [("Retry", 1)], True),
    (0x800C, [("Continue", 1)], False),
    (0xA080, [("Continue", 2), ("Reset MMU", RESET)], False),
    (0x8480, [("Reset MMU", RESET)], False),
    (0xC240, [("Reset MMU", RESET)], False),
    (0x800D, [("Reset MMU", RESET)], False),
    (0x8005, [("Unload", 2), ("Continue", 0)], False),
])
def test_dialog_choices_follow_the_printer(word: int, choices: list[tuple[str, object]], retry: bool) -> None:
    info = describe_error(word)
    assert [(c.label, c.button) for c in info.choices] == choices
    assert info.retryable is retry
    assert info.button_for("retry") == (1 if retry else None)
