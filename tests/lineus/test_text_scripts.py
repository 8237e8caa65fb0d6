"""Text in every script the Hershey fonts draw: the font table checked against Hershey's glyph numbers, every
font drawing all it covers, composed and decomposed accents alike, line breaks and tabs as editors write them."""

from __future__ import annotations

import functools
import string
import unicodedata

import numpy as np
import pytest
from HersheyFonts import HersheyFonts
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.errors import InputError
from fabwire.lineus.plot.text import CYRILLIC, FONTS, GREEK, font_names, text_lines


@functools.cache
def _face(font: str) -> HersheyFonts:
    face = HersheyFonts()
    face.load_default_font(font)
    return face


def _strokes(font: str, key: str) -> list[list[tuple[float, ...]]]:
    return [[tuple(map(float, p)) for p in s] for g in _face(font).glyphs_for_text(key) for s in g.strokes]


def _codes(font: str, keys: str) -> list[int]:
    return [next(iter(_face(font).glyphs_for_text(k))).font_charcode for k in keys]


def _same(a: list[np.ndarray], b: list[np.ndarray]) -> bool:
    return len(a) == len(b) and all(x.shape == y.shape and np.allclose(x, y) for x, y in zip(a, b, strict=True))


def test_the_table_names_every_font() -> None:
    assert set(FONTS) == set(font_names())


@pytest.mark.parametrize("font", sorted(FONTS))
def test_every_font_draws_everything_it_covers(font: str) -> None:
    coverage = FONTS[font]
    drawable = "".join(c for c in coverage.keys if c != " ")
    notes: list[str] = []
    lines = text_lines(drawable, font=font, notes=notes)
    assert not [n for n in notes if "cannot draw" in n], notes
    assert lines
    for char, key in coverage.keys.items():
        if char != " ":
            assert _strokes(font, key), f"{font}: {char!r} sits on key {key!r}, which has no strokes"


# (font, glyph number of Alpha / alpha or А / а: Hershey's numbering, as the font files carry it)
NUMBERED = [("greeks", 527, 627, GREEK), ("greekc", 2027, 2127, GREEK), ("cyrilc_1", 2801, 2901, CYRILLIC)]


@pytest.mark.parametrize(("font", "capital", "small", "alphabet"), NUMBERED)
def test_letters_sit_on_hersheys_glyph_numbers(font: str, capital: int, small: int, alphabet: str) -> None:
    keys = FONTS[font].keys
    assert _codes(font, "".join(keys[c] for c in alphabet)) == list(range(capital, capital + len(alphabet)))
    assert _codes(font, "".join(keys[c.lower()] for c in alphabet)) == list(range(small, small + len(alphabet)))


# (font with glyphs on other keys, its glyph-numbered sibling with the same glyphs)
SIBLINGS = [("greek", "greeks", GREEK), ("timesg", "greekc", GREEK), ("cyrillic", "cyrilc_1", CYRILLIC)]


@pytest.mark.parametrize(("font", "sibling", "alphabet"), SIBLINGS)
def test_rekeyed_fonts_draw_the_same_letter_as_their_numbered_sibling(font: str, sibling: str,
                                                                       alphabet: str) -> None:
    keys, numbered = FONTS[font].keys, FONTS[sibling].keys
    letters = [c for a in alphabet for c in (a, a.lower()) if c in keys]
    assert len(letters) >= 2 * len(alphabet) - 2  # the phonetic Cyrillic set lacks the capital Й only
    for letter in letters:
        assert _strokes(font, keys[letter]) == _strokes(sibling, numbered[letter]), letter


@pytest.mark.parametrize(("font", "letters"), [("mathlow", string.ascii_lowercase),
                                               ("mathupp", string.ascii_uppercase)])
def test_math_fonts_carry_the_roman_letters(font: str, letters: str) -> None:
    for letter in letters:
        assert _strokes(font, FONTS[font].keys[letter]) == _strokes("futural", letter), letter


# (text, font, characters the font cannot draw, where such text comes from)
SENTENCES = [
    ("Съешь же ещё этих мягких французских булок, да выпей чаю", "cyrillic", "",
     "Russian pangram (Wikipedia 'Pangram')"),
    ("Съешь же ещё этих мягких французских булок", "cyrilc_1", "ъьэя",
     "the numbered Complex Cyrillic set ends at Щ"),
    ("Йод ЙОД", "cyrillic", "", "capital Й is И with a breve"),
    ("Ξεσκεπάζω την ψυχοφθόρα βδελυγμία", "greek", "", "Greek pangram with tonos (Wikipedia 'Pangram')"),
    ("Ξεσκεπάζω την ψυχοφθόρα βδελυγμία", "greekc", "", "the same in Hershey's numbered order"),
    ("Ϊ ϋ ς ϑ", "greeks", "", "dialytika, final sigma, script theta"),
    ("Falsches Üben von Xylophonmusik quält jeden größeren Zwerg", "futural", "", "German pangram"),
    ("Παράδειγμα", "futural", "Παράδειγμα", "Greek in a Latin font: named, with the Greek fonts suggested"),
    ("Hello", "greek", "Hello", "Latin in a Greek font"),
]


@pytest.mark.parametrize(("text", "font", "missing", "source"), SENTENCES, ids=[f"{f}:{t[:12]}" for t, f, _, _ in
                                                                                 SENTENCES])
def test_sentences_in_their_fonts(text: str, font: str, missing: str, source: str) -> None:
    notes: list[str] = []
    left_out = {c for c in missing if c.isalpha()}
    if left_out >= {c for c in text if c.isalpha()}:
        with pytest.raises(InputError, match=f"font '{font}' .* has no strokes"):
            text_lines(text, font=font, notes=notes)
        return
    text_lines(text, font=font, notes=notes)
    named = " ".join(n for n in notes if "cannot draw" in n)
    for char in left_out:
        assert repr(char) in named, (char, notes)
    if not left_out:
        assert not named, notes


def test_other_scripts_point_to_their_fonts() -> None:
    notes: list[str] = []
    text_lines("Hi Ωμέγα", notes=notes)
    assert any("for Greek use --font greek" in n for n in notes), notes


# (decomposed, composed, where decomposed text comes from)
DECOMPOSED = [
    ("Cafe\u0301", "Café", "macOS file names (NFD, Unicode TR15)"),
    ("A\u030angstro\u0308m", "Ångström", "text copied from PDFs"),
    ("n\u0303 C\u0327 z\u030c", "ñ Ç ž", "Spanish, French, Czech"),
    ("Е\u0308лка", "Ёлка", "Cyrillic io as Е + diaeresis"),
    ("α\u0301 ι\u0308", "ά ϊ", "Greek tonos and dialytika"),
]


@pytest.mark.parametrize(("nfd", "nfc", "source"), DECOMPOSED, ids=[s for _, _, s in DECOMPOSED])
@pytest.mark.parametrize("font", ["futural", "cyrillic", "greek"])
def test_decomposed_text_draws_like_composed(nfd: str, nfc: str, source: str, font: str) -> None:
    a_notes: list[str] = []
    b_notes: list[str] = []
    try:
        expected = text_lines(nfc, font=font, notes=a_notes)
    except InputError:
        with pytest.raises(InputError):
            text_lines(nfd, font=font, notes=b_notes)
        return
    assert _same(text_lines(nfd, font=font, notes=b_notes), expected)
    assert a_notes == b_notes


_LETTERS = st.sampled_from(list("aeiouAEIOUnczyNCZ") + list("αειουΑΕΙΟΥ") + list("аеиоуАЕИОУ"))
_MARK = st.sampled_from(["\u0300", "\u0301", "\u0302", "\u0303", "\u0308", "\u030a", "\u030c", "\u0327"])


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(_LETTERS, st.lists(_MARK, max_size=2)), min_size=1, max_size=8),
       st.sampled_from(["futural", "greek", "cyrillic"]))
def test_any_text_draws_the_same_in_either_normal_form(parts: list[tuple[str, list[str]]], font: str) -> None:
    text = "".join(base + "".join(marks) for base, marks in parts)
    results = []
    for form in ("NFC", "NFD"):
        notes: list[str] = []
        try:
            results.append((text_lines(unicodedata.normalize(form, text), font=font, notes=notes), notes))
        except InputError as exc:
            results.append(([], [str(exc)]))
    (a, a_notes), (b, b_notes) = results
    assert _same(a, b)
    assert a_notes == b_notes


# (line break, where it comes from)
LINE_BREAKS = [("\n", "Unix"), ("\r\n", "Windows"), ("\r", "classic Mac OS"), ("\u2028", "Unicode LINE SEPARATOR"),
               ("\u0085", "NEXT LINE (EBCDIC text)"), ("\x0c", "form feed")]


@pytest.mark.parametrize(("brk", "source"), LINE_BREAKS, ids=[s for _, s in LINE_BREAKS])
def test_every_line_break_breaks_the_line(brk: str, source: str) -> None:
    notes: list[str] = []
    assert _same(text_lines(f"ab{brk}cd{brk}", notes=notes), text_lines("ab\ncd"))
    assert not notes


def test_a_tab_is_a_gap_to_the_next_stop() -> None:
    notes: list[str] = []
    short, long = text_lines("a\tb", notes=notes), text_lines("aa\tb", notes=notes)
    assert not notes
    b_short, b_long = short[-1], long[-1]  # the b's strokes end each list
    assert np.allclose(b_short, b_long)  # both reach the same stop
    assert b_short[:, 0].min() > max(p[:, 0].max() for p in text_lines("aa"))  # a gap, not a character
    two = text_lines("a\t\tb")[-1]
    assert two[:, 0].min() > b_short[:, 0].max()


@pytest.mark.parametrize(("text", "font"), [("Привет", "cyrillic"), ("αβγ", "greek"), ("Ελλάδα", "greekc"),
                                            ("Café", "futural")])
def test_cli_draws_each_script_in_its_font(text: str, font: str, tmp_path: object) -> None:
    done = run_cli("--json", "lineus", "text", text, "--font", font, "--dry-run", env=cli_env())
    assert done.returncode == 0, done.stderr
    assert "cannot draw" not in done.stderr


def test_cli_latin_in_a_greek_font_is_refused_with_a_pointer() -> None:
    done = run_cli("lineus", "text", "abc", "--font", "greek", "--dry-run", env=cli_env())
    assert done.returncode == 4
    assert "font 'greek' (Greek) has no strokes for 'abc'; for Latin use --font futural" in done.stderr


def test_cli_a_long_text_no_font_draws_is_quoted_short() -> None:
    done = run_cli("lineus", "text", "-", "--dry-run", env=cli_env(), input_text="日本" * 5000)
    assert done.returncode == 4
    line, = done.stderr.splitlines()
    assert line.startswith("fabwire: error: font 'futural' (Latin) has no strokes for '日本日本")
    assert len(line) < 200


def test_the_notes_tell_accented_letters_from_spelled_ones() -> None:
    """A letter drawn with accent strokes and one spelled with other characters are two notes, each naming its
    characters (and what a spelled one became); what no font draws is a third."""
    done = run_cli("lineus", "text", "Ça va? naïve — straße 日", "--dry-run", env=cli_env())
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert "drawn as letters with accent strokes: 'Ç' (U+00C7), 'ï' (U+00EF)" in lines
    assert "spelled with other characters: '—' (U+2014) as '-', 'ß' (U+00DF) as 'ss'" in lines
    assert any(line.startswith("font 'futural' (Latin) cannot draw '日' (U+65E5)") for line in lines), lines
