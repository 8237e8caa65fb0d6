"""Text in a single-stroke Hershey font: each line of strokes drawn once, no outlines to retrace.

Text is first brought to Unicode's composed form (NFC, UAX #15), so a letter typed as base + combining accent
(macOS file names, text copied from PDFs) draws like the precomposed one. Each font draws one script (`FONTS`):
the Hershey files key their Greek and Cyrillic glyphs by ASCII letters, and the table maps each Greek or Cyrillic
letter to the key its glyph sits on. Other letters are built the way type designers compose them (Unicode
canonical decomposition): the base glyph plus accent strokes placed over or under it (é = e + ´, Ё = Е + ¨);
letters that do not decompose fall back to their usual spelling (ß → ss, æ → ae) or their compatibility form
(ﬁ → fi). Every character drawn differently, or not at all, is named in the notes. Lines break at every Unicode
line boundary (`\n`, `\r\n`, `\r`, U+2028 …); a tab is a gap to the next stop of `TAB_STOP` spaces.
"""

from __future__ import annotations

import functools
import math
import string
import unicodedata
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from HersheyFonts import HersheyFonts

from fabwire.errors import InputError, excerpt
from fabwire.lineus.plot.geometry import FloatArray, Polylines

DEFAULT_FONT = "futural"
LINE_SPACING = 1.4
"""Baseline distance as a multiple of the font's cap height."""
TAB_STOP = 4
"""A tab moves on to the next multiple of this many space widths."""
ACCENT_HEIGHT = 0.28
"""Height of an accent as a share of the cap height; it sits this far above the letter's top, a third of it apart."""


def _circle(cx: float, cy: float, r: float, n: int = 12) -> list[tuple[float, float]]:
    return [(cx + r * math.cos(2 * math.pi * k / n), cy + r * math.sin(2 * math.pi * k / n)) for k in range(n + 1)]


@dataclass(frozen=True)
class _Mark:
    """Accent strokes in a box: x from -0.5 to 0.5 of the accent width, y from 0 (near the letter) to 1, y up;
    `place` is 'above', 'below' (hanging from the baseline) or 'over' (across the letter's own box)."""

    strokes: tuple[tuple[tuple[float, float], ...], ...]
    place: str = "above"


_MARKS: dict[str, _Mark] = {
    "\u0300": _Mark((((0.2, 0.0), (-0.2, 1.0)),)),  # grave
    "\u0301": _Mark((((-0.2, 0.0), (0.2, 1.0)),)),  # acute
    "\u0302": _Mark((((-0.45, 0.0), (0.0, 1.0), (0.45, 0.0)),)),  # circumflex
    "\u0303": _Mark((((-0.5, 0.2), (-0.25, 0.8), (0.0, 0.5), (0.25, 0.2), (0.5, 0.8)),)),  # tilde
    "\u0304": _Mark((((-0.45, 0.5), (0.45, 0.5)),)),  # macron
    "\u0306": _Mark((((-0.45, 1.0), (-0.3, 0.3), (0.0, 0.0), (0.3, 0.3), (0.45, 1.0)),)),  # breve
    "\u0307": _Mark((tuple(_circle(0.0, 0.5, 0.14)),)),  # dot above
    "\u0308": _Mark((tuple(_circle(-0.3, 0.5, 0.14)), tuple(_circle(0.3, 0.5, 0.14)))),  # diaeresis
    "\u030a": _Mark((tuple(_circle(0.0, 0.5, 0.4)),)),  # ring above
    "\u030b": _Mark((((-0.4, 0.0), (-0.1, 1.0)), ((0.1, 0.0), (0.4, 1.0)))),  # double acute
    "\u030c": _Mark((((-0.45, 1.0), (0.0, 0.0), (0.45, 1.0)),)),  # caron
    "\u0327": _Mark((((0.0, 1.0), (0.15, 0.5), (-0.25, 0.0)),), "below"),  # cedilla
    "\u0328": _Mark((((0.3, 1.0), (0.0, 0.5), (0.4, 0.0)),), "below"),  # ogonek
    "\u0337": _Mark((((-0.35, 0.35), (0.35, 0.65)),), "over"),  # short solidus overlay (ł)
    "\u0338": _Mark((((-0.5, -0.05), (0.5, 1.05)),), "over"),  # long solidus overlay (ø)
    "\u0335": _Mark((((-0.3, 0.6), (0.3, 0.6)),), "over"),  # short stroke overlay (đ, ħ)
}
_FALLBACK = {
    "ß": "ss", "ẞ": "SS", "æ": "ae", "Æ": "AE", "œ": "oe", "Œ": "OE", "þ": "th", "Þ": "Th", "ð": "d\u0335",
    "Ð": "D\u0335", "đ": "d\u0335", "Đ": "D\u0335", "ħ": "h\u0335", "Ħ": "H\u0335", "ø": "o\u0338", "Ø": "O\u0338",
    "ł": "l\u0337", "Ł": "L\u0337", "ı": "i", "‘": "'", "’": "'", "‚": ",", "“": '"', "”": '"', "„": '"',
    "–": "-", "—": "-", "‐": "-", "−": "-", "…": "...", "«": "<<", "»": ">>", "\u00a0": " ", "€": "EUR",
    "£": "GBP", "©": "(c)", "®": "(R)", "™": "TM", "×": "x", "·": ".", "ς": "σ", "ϑ": "θ", "ϕ": "φ", "ϐ": "β",
}


# -- which characters each font draws, and on which key ----------------------------------------------------------

_ASCII = string.digits + string.ascii_letters + string.punctuation + " "
_NON_LETTERS = "".join(c for c in _ASCII if not c.isalpha())
GREEK = "ΑΒΓΔΕΖΗΘΙΚΛΜΝΞΟΠΡΣΤΥΦΧΨΩ"
"""The Greek alphabet in Hershey's glyph order (Simplex Greek capitals 527-550, small letters 627-650)."""
CYRILLIC = "АБВГДЕЖЗИЙКЛМНОПРСТУФХЦЧШЩ"
"""The Russian alphabet as far as Hershey's Complex Cyrillic numbers it (capitals 2801-2826, small 2901-2926)."""


def _keyed(letters: str, keys: str) -> dict[str, str]:
    """Capital letters on `keys` and their small letters on the keys' small letters."""
    pairs = dict(zip(letters, keys, strict=True))
    return {**pairs, **{a.lower(): k.lower() for a, k in pairs.items()}}


def _same(chars: str) -> dict[str, str]:
    return {c: c for c in chars}


@dataclass(frozen=True)
class FontCoverage:
    """What a font draws: `script` ("Latin", "Greek", "Cyrillic", or "symbols" for fonts of signs keyed by
    ASCII), `keys` each drawable character to the ASCII key its glyph sits on, `source` where the layout is from."""

    script: str
    keys: Mapping[str, str]
    source: str


_LATIN = FontCoverage("Latin", _same(_ASCII), "Hershey's Roman, Script, Gothic and Italic sets: ASCII as it is")
_GREEK_HERSHEY = FontCoverage(
    "Greek", {**_same(_NON_LETTERS), **_keyed(GREEK, string.ascii_uppercase[:24])},
    "Hershey Greek in Hershey's own order: A-X are Alpha-Omega (glyph numbers 527-550 simplex, 2027-2050 complex)")
_GREEK_SYMBOL = FontCoverage(
    "Greek", {**_same(_NON_LETTERS), **_keyed(GREEK, "ABGDEZHQIKLMNXOPRSTUFCYW")},
    "Hershey Greek on the Adobe Symbol font's keys (C = Chi, F = Phi, Q = Theta, W = Omega …): the same glyphs "
    "as 'greeks' / 'greekc' in Symbol order")
_CYRILLIC_HERSHEY = FontCoverage(
    "Cyrillic", {**_same(_NON_LETTERS), **_keyed(CYRILLIC, string.ascii_uppercase)},
    "Hershey Complex Cyrillic in alphabet order: A-Z are А-Щ (glyph numbers 2801-2826, 2901-2926); "
    "Ъ Ы Ь Э Ю Я are not in the set")
_CYRILLIC_PHONETIC = FontCoverage(
    "Cyrillic",
    {**_same("".join(c for c in _NON_LETTERS if c not in "$%&[]^_`{|}~")),
     **_keyed("АБВГДЖЗИКЛМНОПРСТУФХЧШЩЭЮ", "ABVGDHZIKLMNOPRSTYFXJQWCU"),
     "Е": "[", "е": "{", "Ъ": "]", "ъ": "|", "Я": "^", "я": "}", "Ь": "_", "ь": "~", "Ц": "`", "ц": "%",
     "Ы": "$", "ы": "&", "й": "e"},
    "Hershey Complex Cyrillic keyed by sound (V = В, H = Ж, J = Ч, Q = Ш …; Е on [ {, Ц on ` %, Ы on $ &, "
    "Ъ on ] |, Ь on _ ~, Я on ^ }): the glyphs of 'cyrilc_1' and its missing Ъ Ы Ь Э Ю Я; capital Й is "
    "И with a breve")
_SYMBOLS = FontCoverage("symbols", _same(_ASCII), "signs (astrological, musical, weather, map markers …) on "
                                                   "ASCII keys: type the key of the sign wanted")
FONTS: dict[str, FontCoverage] = {
    "futural": _LATIN, "futuram": _LATIN, "rowmans": _LATIN, "rowmand": _LATIN, "rowmant": _LATIN,
    "timesr": _LATIN, "timesrb": _LATIN, "timesi": _LATIN, "timesib": _LATIN, "cursive": _LATIN,
    "scripts": _LATIN, "scriptc": _LATIN, "gothiceng": _LATIN, "gothicger": _LATIN, "gothicita": _LATIN,
    "gothgbt": _LATIN, "gothgrt": _LATIN, "gothitt": _LATIN,
    "mathlow": FontCoverage("Latin", {**_same(" %*+,-./0123456789<=>[\\]{}"),
                                      **{c: c.upper() for c in string.ascii_lowercase}},
                            "Hershey math set, small letters: A-Z carry a-z, the other keys math signs"),
    "mathupp": FontCoverage("Latin", _same(" %*+-/0123456789<=>[\\]" + string.ascii_uppercase),
                            "Hershey math set, capitals: A-Z as they are, the small-letter keys math signs"),
    "greek": _GREEK_SYMBOL, "timesg": _GREEK_SYMBOL, "greeks": _GREEK_HERSHEY, "greekc": _GREEK_HERSHEY,
    "cyrillic": _CYRILLIC_PHONETIC, "cyrilc_1": _CYRILLIC_HERSHEY,
    "astrology": _SYMBOLS,
    "markers": FontCoverage("symbols", _same(" " + string.ascii_letters[:16] + string.ascii_uppercase[:16]),
                            "map markers on A-P and a-p; the other keys are blank"),
    "meteorology": _SYMBOLS, "music": _SYMBOLS, "symbolic": _SYMBOLS,
    "japanese": _SYMBOLS,
}
"""Every font `font_names` offers, with the characters it draws (HersheyFonts' default fonts, from the Hershey
fonts of the U.S. National Bureau of Standards as distributed in .jhf files)."""


def font_names() -> list[str]:
    return list(HersheyFonts().default_font_names)


@dataclass(frozen=True)
class _Face:
    """A loaded font and the characters it draws."""

    name: str
    hershey: HersheyFonts
    coverage: FontCoverage


@functools.lru_cache(maxsize=8)
def _font(name: str) -> _Face:
    font = HersheyFonts()
    if name not in font.default_font_names or name not in FONTS:
        raise InputError(f"unknown font {name!r}; choose one of: {', '.join(font.default_font_names)}")
    font.load_default_font(name)
    return _Face(name, font, FONTS[name])


def _glyph(face: _Face, char: str) -> object | None:
    """The glyph that draws `char` in this font (through the font's key for it), or None."""
    key = face.coverage.keys.get(char)
    found = list(face.hershey.glyphs_for_text(key)) if key is not None else []
    return found[0] if found else None


def _spell(face: _Face, char: str, depth: int = 0) -> list[tuple[str, list[str]]] | None:
    """`char` as (base letter the font has, accent marks) pairs, or None when it cannot be built."""
    if _glyph(face, char) is not None:
        return [(char, [])]
    if depth > 3:
        return None
    if char in _FALLBACK:
        return _spell_text(face, _FALLBACK[char], depth + 1)
    decomposed = unicodedata.normalize("NFD", char)
    if len(decomposed) > 1 and _glyph(face, decomposed[0]) is not None:
        marks = list(decomposed[1:])
        if all(m in _MARKS for m in marks):
            return [(decomposed[0], marks)]
    compatible = unicodedata.normalize("NFKD", char)
    if compatible != char:
        return _spell_text(face, compatible, depth + 1)
    return None


def _spell_text(face: _Face, text: str, depth: int) -> list[tuple[str, list[str]]] | None:
    out: list[tuple[str, list[str]]] = []
    for char in text:
        if char in _MARKS and out:
            out[-1][1].append(char)
            continue
        part = _spell(face, char, depth)
        if part is None:
            return None
        out.extend(part)
    return out


def _clusters(line: str) -> list[str]:
    """A line as user-perceived characters: each base character with the combining marks that follow it."""
    out: list[str] = []
    for char in line:
        if out and unicodedata.combining(char):
            out[-1] += char
        else:
            out.append(char)
    return out


def _spell_cluster(face: _Face, cluster: str) -> list[tuple[str, list[str]]] | None:
    """A base character and its combining marks (left after NFC when no precomposed letter exists)."""
    spelled = _spell(face, cluster[0])
    if spelled is None or len(cluster) == 1:
        return spelled
    if not spelled or not all(mark in _MARKS for mark in cluster[1:]):
        return None
    spelled[-1][1].extend(cluster[1:])
    return spelled


def _mark_strokes(mark: _Mark, box: tuple[float, float, float, float], cap: float, baseline: float) -> Polylines:
    """A mark's strokes placed for a glyph whose drawn box is (x0, top, x1, bottom), glyph units, y down."""
    x0, top, x1, bottom = box
    cx = (x0 + x1) / 2
    if mark.place == "over":
        w, h, y0 = max(x1 - x0, cap * 0.3), bottom - top, bottom
    else:
        h = cap * ACCENT_HEIGHT
        w = max(min(x1 - x0, cap * 0.6), cap * 0.3)
        y0 = top - h / 3 if mark.place == "above" else baseline + h
    out: Polylines = []
    for stroke in mark.strokes:
        pts = np.array(stroke, dtype=float)
        out.append(np.column_stack([cx + pts[:, 0] * w, y0 - pts[:, 1] * h]))
    return out


def text_lines(text: str, *, font: str = DEFAULT_FONT, cap_height: float = 1.0,
               notes: list[str] | None = None) -> Polylines:
    """Strokes of `text` with y up, the first baseline at y = 0, letters `cap_height` tall.

    Characters built from a base letter and accents, or spelled another way, and characters that cannot be drawn
    at all, are named in `notes`. InputError when nothing at all can be drawn.
    """
    text = unicodedata.normalize("NFC", text)
    if not text.strip():
        raise InputError("the text is empty")
    face = _font(font)
    top, baseline = _cap_span(face)
    cap = baseline - top
    scale = cap_height / cap
    space = _glyph(face, " ")
    tab = TAB_STOP * float(space.char_width if space is not None else cap / 2)  # type: ignore[attr-defined]
    result: Polylines = []
    missing: list[str] = []
    accented: list[str] = []
    respelled: list[str] = []
    for row, line in enumerate(text.splitlines()):
        x = 0.0
        for cluster in _clusters(line):
            if cluster == "\t":
                x = (math.floor(x / tab + 1e-9) + 1) * tab
                continue
            spelled = _spell_cluster(face, cluster)
            if spelled is None:
                missing.append(cluster)
                continue
            if spelled != [(cluster, [])]:
                if any(marks for _, marks in spelled):
                    accented.append(cluster)
                else:
                    respelled.append(f"{_listing([cluster])} as {''.join(base for base, _ in spelled)!r}")
            for base, marks in spelled:
                glyph = _glyph(face, base)
                shift = np.array([x - glyph.left_offset, 0.0])  # type: ignore[attr-defined]
                strokes = [np.array(s, dtype=float) + shift for s in glyph.strokes if len(s)]  # type: ignore[attr-defined]
                if strokes:
                    allp = np.concatenate(strokes)
                    box = (float(allp[:, 0].min()), float(allp[:, 1].min()), float(allp[:, 0].max()),
                           float(allp[:, 1].max()))
                else:
                    box = (x, top, x + glyph.char_width, baseline)  # type: ignore[attr-defined]
                for mark in marks:
                    strokes.extend(_mark_strokes(_MARKS[mark], box, cap, baseline))
                for poly in strokes:
                    placed: FloatArray = poly * scale
                    # Hershey glyphs run y down from the cap line; flip so y is up with the baseline at 0.
                    placed[:, 1] = (baseline * scale - placed[:, 1]) - row * LINE_SPACING * cap_height
                    result.append(placed)
                x += float(glyph.char_width)  # type: ignore[attr-defined]
    script = face.coverage.script
    if not result:
        raise InputError(f"font {font!r} ({script}) has no strokes for {excerpt(text, 40)}{_suggestion(missing)}")
    if notes is not None:
        if script == "symbols":
            notes.append(f"font {font!r} draws signs, not letters: each character typed draws the sign on its key")
        if accented:
            notes.append(f"drawn as letters with accent strokes: {_listing(accented)}")
        if respelled:
            unique = list(dict.fromkeys(respelled))
            more = " …" if len(unique) > 20 else ""
            notes.append(f"spelled with other characters: {', '.join(unique[:20])}{more}")
        if missing:
            notes.append(f"font {font!r} ({script}) cannot draw {_listing(missing)}: left out{_suggestion(missing)}")
    return result


def _suggestion(missing: list[str]) -> str:
    """'; for Greek use --font greek, …' when the characters left out belong to a script other fonts draw."""
    for script in dict.fromkeys(c.script for c in FONTS.values() if c.script != "symbols"):
        if any(unicodedata.name(c[0], "").startswith(script.upper() + " ") for c in missing):
            fonts = [name for name, c in FONTS.items() if c.script == script]
            return f"; for {script} use --font {', '.join(fonts[:4])}{' …' if len(fonts) > 4 else ''}"
    return ""


def _listing(chars: list[str]) -> str:
    unique = list(dict.fromkeys(chars))
    named = (f"{c!r} ({' '.join(f'U+{ord(u):04X}' for u in c)})" for c in unique[:20])
    return ", ".join(named) + (" …" if len(unique) > 20 else "")


def _cap_span(face: _Face) -> tuple[float, float]:
    """(cap line, baseline) y of the font, measured on 'H' (y down)."""
    ys = [float(p[1]) for seg in face.hershey.lines_for_text("H") for p in seg]
    if not ys or max(ys) <= min(ys):
        return (0.0, 1.0)
    return (min(ys), max(ys))
