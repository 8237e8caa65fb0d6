"""The one error tree every layer raises, so the CLI can map each kind to its own exit code."""

from __future__ import annotations

import re


class FabwireError(Exception):
    """Base of everything fabwire raises on purpose."""

    exit_code = 1


class ConfigError(FabwireError):
    """The named-device configuration file (or a device name) is wrong."""

    exit_code = 3


class ConfigWarning(UserWarning):
    """The configuration file is wrong, but the command did not need it (it was given an address)."""


class InputError(FabwireError):
    """A file or argument given by the user cannot be used (malformed, empty, out of range)."""

    exit_code = 4


class ProtocolError(FabwireError):
    """Bytes that break a protocol's grammar."""


class LocalProtocolError(ProtocolError):
    """We were asked to send something the protocol cannot carry."""

    exit_code = 5


class RemoteProtocolError(ProtocolError):
    """The peer sent something the protocol does not allow."""

    exit_code = 6


class DeviceBusy(InputError):
    """The device is in the middle of something else (a job, a drawing): wait for it or cancel it first."""


class DeviceError(FabwireError):
    """The machine reported an error code; `meaning` says it in words."""

    exit_code = 7

    def __init__(self, code: int | str, meaning: str, *, action: str = "") -> None:
        """`code` is the machine's own code for the error; a machine without codes (the Line-us answers a bare
        `error`) gives "" and `meaning` alone is shown."""
        self.code = code
        self.meaning = meaning
        self.action = action
        text = f"device error {code}: {meaning}" if code != "" else meaning
        if action:
            text += f" — {action}"
        super().__init__(text)


class LinkError(FabwireError, ConnectionError):
    """The link to the device could not be opened or was lost."""

    exit_code = 8


class LinkClosed(LinkError):
    """The peer closed the link (EOF) or it was closed locally."""


class LinkTimeout(FabwireError, TimeoutError):
    """The device did not answer in time."""

    exit_code = 9


EXIT_INTERRUPTED = 130


class PrintCancelled(DeviceError):
    """A followed print the printer stopped before it finished (its panel, another client, or this command);
    `percent`: its last progress shown, when there was one."""

    def __init__(self, percent: int | None) -> None:
        self.percent = percent
        super().__init__("", "the print was cancelled before it finished" + self.at)

    @property
    def at(self) -> str:
        return f" (at {self.percent} %)" if self.percent is not None else ""


class CancelledAsAsked(FabwireError):
    """A job the command's own user cancelled while following it (a key of the live view): it ended as asked,
    not by a fault, so it exits as an interrupted command does."""

    exit_code = EXIT_INTERRUPTED


class FollowInterrupted(FabwireError):
    """Ctrl-C while following a job the machine has already taken (a print, a tool change): it goes on."""

    exit_code = EXIT_INTERRUPTED


def excerpt(value: str | bytes, limit: int = 40) -> str:
    """`value` quoted with its escapes visible, as `repr` shows it, in at most about `limit` + 4 characters: a
    message quoting outside text stays one short line however long or exotic that text is (`'\\U0001f600'` takes
    12 characters for one). A cut is marked with `…` inside the quotes."""
    shown = repr(value)
    if len(shown) <= limit + 3:
        return shown
    cut = value[:limit]
    while len(repr(cut)) > limit + 3:
        cut = cut[:-1]
    quoted = repr(cut)
    return quoted[:-1] + "…" + quoted[-1]


def nearest(word: str, choices: object) -> str | None:
    """The choice nearest `word` as a typo is near it (difflib), or None."""
    import difflib

    names = [str(c) for c in choices]  # type: ignore[attr-defined]
    match = difflib.get_close_matches(word[:100], names, n=1, cutoff=0.6)
    return match[0] if match else None


def closest(word: str, choices: object) -> str:
    """` (did you mean 'x'?)` for the choice nearest `word`, or nothing."""
    match = nearest(word, choices)
    return f" (did you mean {excerpt(match)}?)" if match else ""


_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f]")
"""Control characters (C0 and C1, tab and newline excepted) that outside text must not bring to a terminal."""


def visible(text: str) -> str:
    """`text` with each control character written as `\\xNN`: text a device or a broker sent is shown, never
    obeyed (an escape sequence could rewrite the terminal)."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m[0]):02x}", text) if _CONTROL.search(text) else text
