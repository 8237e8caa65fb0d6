"""Every string a user types that ends up inside an XYZv3 command, checked in one place.

The commands carry these strings between fixed delimiters (`config=name:[…]`, `config=ssid:[ssid,password,ch]`,
`upload=<name>,<size>`), so a delimiter, a line break or a character the firmware cannot show is refused here
with an InputError that says what is allowed. What passes is encoded on the wire as UTF-8 (`encode_text`).
"""

from __future__ import annotations

import re
import unicodedata
from pathlib import PurePath

from fabwire.errors import InputError

LANGUAGES = ("en", "fr", "it", "de", "es", "jp")
"""Display languages of the firmware (`l:`; miniMover's xyzv3.h)."""
UPLOAD_NAME_LIMIT = 128
PRINTER_NAME_LIMIT = 16
"""`n:` is reported space-padded to 16 characters."""
SSID_LIMIT = 32
"""IEEE 802.11: an SSID is at most 32 bytes."""
DEFAULT_UPLOAD_NAME = "fabwire.3w"

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _printable_ascii(text: str) -> bool:
    return text.isascii() and text.isprintable() and not _starts_a_command(text)


def _starts_a_command(text: str) -> bool:
    """`XYZv3/` inside a value would start a new command for the printer's splitter."""
    return "XYZv3/" in text


def upload_name(text: str) -> str:
    """A name given for an upload: 1-128 printable ASCII characters without a comma (the field separator)."""
    if not text or len(text) > UPLOAD_NAME_LIMIT or "," in text or not _printable_ascii(text):
        raise InputError(f"upload name {text!r} must be 1-{UPLOAD_NAME_LIMIT} printable ASCII characters "
                         "without commas")
    return text


def derived_upload_name(source: str | PurePath | None, suffix: str = ".3w") -> str:
    """A safe upload name from a local file name: accents folded, anything but letters, digits, `.`, `_`, `-`
    made `_`, at most 32 characters before the suffix (official clients send fixed names such as temp.gcode)."""
    if source is None:
        return DEFAULT_UPLOAD_NAME
    stem = PurePath(source).stem
    folded = unicodedata.normalize("NFKD", stem).encode("ascii", "ignore").decode("ascii")
    safe = _SAFE.sub("_", folded).strip("._-")[:32].rstrip("._-")
    return (safe or DEFAULT_UPLOAD_NAME.removesuffix(".3w")) + suffix


def printer_name(text: str) -> str:
    """A printer name: 1-16 printable ASCII characters without brackets (the display shows ASCII only)."""
    if not text or len(text) > PRINTER_NAME_LIMIT or any(c in text for c in "[]") or not _printable_ascii(text):
        raise InputError(f"printer name {text!r} must be 1-{PRINTER_NAME_LIMIT} printable ASCII characters "
                         "without brackets")
    return text


def ssid(text: str) -> str:
    """A Wi-Fi network name: 1-32 bytes of UTF-8, printable, without `,` or brackets (the command's delimiters)."""
    size = len(text.encode("utf-8", "surrogatepass"))
    if (not text or size > SSID_LIMIT or not text.isprintable() or any(c in text for c in ",[]")
            or _starts_a_command(text)):
        raise InputError(f"Wi-Fi network name {text!r} must be 1-{SSID_LIMIT} bytes of printable text without "
                         "',' or brackets")
    _utf8(text, "Wi-Fi network name")
    return text


def wifi_password(text: str) -> str:
    """A Wi-Fi key: up to 63 printable ASCII characters (WPA passphrases are 8-63, WEP keys 5 or 13) or 64 hex
    digits, or empty for an open network; never `,` or brackets, which end the command's fields."""
    if len(text) > 64 or (len(text) == 64 and not re.fullmatch(r"[0-9A-Fa-f]{64}", text)) or (
            text and not _printable_ascii(text)):
        raise InputError("Wi-Fi password must be up to 63 printable ASCII characters (or 64 hex digits)")
    if any(c in text for c in ",[]"):
        raise InputError("the printer cannot take a Wi-Fi password containing ',' or brackets")
    return text


def language(code: str) -> str:
    """A display language the firmware has, in lower case."""
    folded = code.strip().lower()
    if folded not in LANGUAGES:
        raise InputError(f"unknown display language {code!r}; the firmware has {', '.join(LANGUAGES)}")
    return folded


ENERGY_MINUTES = range(10)
"""`config=energy:[N]` takes 0-9 minutes of idle (miniMover's xyzv3.cpp)."""


def energy_minutes(minutes: int) -> int:
    """Minutes of idle before the lights go off: a whole number 0-9."""
    if minutes not in ENERGY_MINUTES:
        raise InputError(f"energy saving takes 0-9 minutes, not {minutes}")
    return minutes


def _utf8(text: str, what: str) -> None:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise InputError(f"{what} {text!r} is not valid Unicode text") from None


def encode_text(text: str) -> bytes:
    """The wire bytes of a command text (UTF-8; everything the checks above let through encodes)."""
    return text.encode("utf-8", "surrogateescape")
