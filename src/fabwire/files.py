"""Reading files a user or a state directory hands over, with a bound: a path to /dev/zero or a huge file must
cost no more memory than the largest real one."""

from __future__ import annotations

from pathlib import Path


def read_bounded(path: Path, limit: int) -> bytes | None:
    """The file's bytes, or None when it holds more than `limit` bytes (reading no further than one past it).

    OSError (and ValueError for a NUL in the name) pass to the caller, who words them for its file.
    """
    with path.open("rb") as handle:
        raw = handle.read(limit + 1)
    return raw if len(raw) <= limit else None


def same_file(a: Path, b: Path) -> bool:
    """True when both names lead to one existing file (links and relative spellings included)."""
    try:
        return a.exists() and b.exists() and a.samefile(b)
    except OSError:
        return False
