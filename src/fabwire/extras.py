"""Optional parts of the install: which extra brings which package, and the message when one is missing.

The base install (`pip install fabwire`) drives da Vinci printers and the MMU3; the drawing stack comes with
`fabwire[lineus]`, the agent with `fabwire[serve]`, the vpype plugin with `fabwire[vpype]`; `fabwire[all]` has all.
"""

from __future__ import annotations

from fabwire.errors import FabwireError

EXTRA_OF = {
    "svgelements": "lineus",
    "HersheyFonts": "lineus",
    "zeroconf": "lineus",
    "PIL": "lineus",
    "shapely": "lineus",
    "fastapi": "serve",
    "uvicorn": "serve",
    "websockets": "serve",
    "vpype": "vpype",
    "vpype_cli": "vpype",
}


class MissingExtra(FabwireError):
    """A command needs a package from an extra that is not installed."""

    exit_code = 3

    def __init__(self, package: str, extra: str) -> None:
        self.package = package
        self.extra = extra
        super().__init__(f"this needs {package!r}, part of fabwire's [{extra}] extra: "
                         f"pip install 'fabwire[{extra}]' (or 'fabwire[all]' for everything)")


def missing_extra(exc: ImportError) -> MissingExtra | None:
    """The MissingExtra an import failure amounts to, or None when it is not about an optional package."""
    name = (getattr(exc, "name", None) or "").partition(".")[0]
    extra = EXTRA_OF.get(name)
    return MissingExtra(name, extra) if extra else None


def first_missing(extra: str) -> MissingExtra | None:
    """The MissingExtra for the first package of `extra` that is not installed, or None when all are."""
    import importlib.util

    for package, owner in EXTRA_OF.items():
        if owner == extra and importlib.util.find_spec(package) is None:
            return MissingExtra(package, extra)
    return None
