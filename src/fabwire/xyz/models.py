"""The da Vinci model table: what each printer reports as `p:`, and which .3w flavour it accepts."""

from __future__ import annotations

import enum
import re

import msgspec

from fabwire.errors import InputError, excerpt


class FileFormat(enum.Enum):
    """The .3w flavour a model's firmware accepts (container version + body cipher)."""

    V2_ZIP = "v2-zip"
    """Container v2, body zipped then AES-128-CBC (`TagEa128`); 1.0/1.1/2.0 generation."""
    V2 = "v2"
    """Container v2, body AES-256-ECB (`TagEJ256`), encrypted header."""
    V5 = "v5"
    """Container v5, body AES-256-ECB (`TagEJ256`), plaintext header."""

    @property
    def container(self) -> int:
        return 5 if self is FileFormat.V5 else 2

    @property
    def zipped(self) -> bool:
        return self is FileFormat.V2_ZIP


class PrinterModel(msgspec.Struct, frozen=True):
    model_number: str
    """What the printer reports in the `p:` status line, e.g. `dv1MX0A000`."""
    name: str
    file_id: str
    """The `; machine =` value a .3w for this model carries (miniMover's fileNum); not unique across models."""
    serial_prefixes: tuple[str, ...]
    """First six characters of the serial number (`i:`); not unique, so never used to identify a model."""
    web_id: str | None
    file_format: FileFormat
    v3_protocol: bool
    """Speaks XYZv3 (the 1.1 Plus only for status and upload)."""
    tuning_menu: bool
    heated_bed: bool
    dual_extruder: bool
    wifi: bool
    scanner: bool
    laser: bool
    build_volume_mm: tuple[int, int, int]
    aliases: tuple[str, ...] = ()
    note: str = ""

    @property
    def container(self) -> int:
        return self.file_format.container

    @property
    def zipped(self) -> bool:
        return self.file_format.zipped


_V2Z, _V2, _V5 = FileFormat.V2_ZIP, FileFormat.V2, FileFormat.V5


def _m(
    number: str, file_id: str, serials: str, web: str | None, fmt: FileFormat, flags: str,
    size: tuple[int, int, int], name: str, aliases: tuple[str, ...] = (), note: str = "",
) -> PrinterModel:
    """One table row; `flags` spells v3/menu/hbed/dual/wifi/scan/laser as Y or n, in that order."""
    f = [c == "Y" for c in flags]
    return PrinterModel(
        model_number=number, name=name, file_id=file_id, serial_prefixes=tuple(serials.split()), web_id=web,
        file_format=fmt, v3_protocol=f[0], tuning_menu=f[1], heated_bed=f[2], dual_extruder=f[3], wifi=f[4],
        scanner=f[5], laser=f[6], build_volume_mm=size, aliases=aliases, note=note,
    )


MODELS: tuple[PrinterModel, ...] = (
    _m("dvF100B000", "daVinciF10", "3DP01P", "davincif10_V2", _V2Z, "nYYnnnn", (200, 200, 200), "da Vinci 1.0",
       ("1.0", "f10")),
    _m("dvF100A000", "daVinciF10", "3F10AP", "dvF100A000_V2", _V2Z, "nYYnnnn", (200, 200, 200), "da Vinci 1.0A"),
    _m("dvF10SA000", "daVinciF10", "3S10AP", "dvF10SA000_V2", _V2Z, "nYYnnYY", (200, 200, 190), "da Vinci 1.0 AiO",
       ("1.0 all-in-one",)),
    _m("dvF110B000", "daVinciF11", "3F11XP", "dvF110B000_V2", _V2Z, "YYYnYnn", (200, 200, 200),
       "da Vinci 1.1 Plus", ("1.1", "f11"), "speaks XYZv3 only for status and upload"),
    _m("dvF200B000", "daVinciF20", "3F20XP", "davincif20_V2", _V2Z, "nYYYnnn", (200, 200, 150),
       "da Vinci 2.0 Duo", ("2.0", "f20")),
    _m("dvF200A000", "daVinciF20", "3F20AP", "dvF200A000_V2", _V2Z, "nYYYnnn", (200, 200, 150),
       "da Vinci 2.0A Duo"),
    _m("dv1J00A000", "daVinciJR10", "3F1J0X", "dv1J00A000_V2", _V2, "YYnnnnn", (150, 150, 150),
       "da Vinci Jr. 1.0", ("jr", "junior")),
    _m("dv1JA0A000", "dv1JA0A000", "3F1JAP", "dv1JA0A000_V2", _V2, "YYnnnnY", (175, 175, 175), "da Vinci Jr. 1.0A"),
    _m("dv1JW0A000", "daVinciJR10W", "3F1JWP", "dv1JW0A000_V2", _V2, "YYnnYnn", (150, 150, 150),
       "da Vinci Jr. 1.0w"),
    _m("dv1JS0A000", "dv1JSOA000", "3F1JSP", "dv1JS0A000_V2", _V2, "YYnnYYY", (150, 150, 150),
       "da Vinci Jr. 1.0 3in1"),
    _m("dv1JSOA000", "daVinciJR10S", "3F1JOP", None, _V5, "YYnnYYY", (150, 150, 150),
       "da Vinci Jr. 1.0 3in1 (Open filament)", ("jr 1.0 3in1 open filament", "jr 3in1 open")),
    _m("dv2JW0A000", "daVinciJR20W", "3F2JWP", "dv2JW0A000_V2", _V2, "YYnYYnn", (150, 150, 150),
       "da Vinci Jr. 2.0 Mix", ("jr 2.0", "jr mix")),
    _m("dv1MX0A000", "dv1MX0A000", "3FM1XP", "dv1MX0A000_V2", _V2, "Ynnnnnn", (150, 150, 150),
       "da Vinci miniMaker", ("mini maker",)),
    _m("dv1MW0A000", "dv1MW0A000", "3FM1WP", "dv1MW0A000_V2", _V2, "YnnnYnn", (150, 150, 150), "da Vinci mini w",
       ("mini",)),
    _m("dv1MW0B000", "dv1MW0B000", "3FM1JP", "dv1MW0B000_V2", _V2, "YnnnYnn", (150, 150, 150), "da Vinci mini wA",
       note="existence doubted; XYZware treats it as a mini w"),
    _m("dv1MW0C000", "dv1MW0C000", "3FM3WP", "dv1MW0C000_V2", _V2, "YnnnYnn", (150, 150, 150), "da Vinci mini w+",
       ("mini w plus",)),
    _m("dv1NX0A000", "dv1NX0A000", "3FN1XP 3FNAXP", "dv1NX0A000_V2", _V2, "Ynnnnnn", (120, 120, 120),
       "da Vinci nano", (), "firmware 3.x wants v5 files"),
    _m("dv1NW0A000", "dv1NW0A000", "3FNAWP", "dv1NW0A000_V2", _V2, "YnnnYnn", (120, 120, 120), "da Vinci nano w"),
    _m("dv1JP0A000", "dv1JP0A000", "3F1JPP", "dv1JP0A000_V2", _V5, "YYnnnnn", (150, 150, 150),
       "da Vinci Jr. 1.0 Pro", ("jr pro",)),
    _m("dv1JPWA000", "dv1JPWA000", "3F1JPW", "dv1JPWA000_V2", _V5, "YYnnYnn", (150, 150, 150),
       "da Vinci Jr. 1.0w Pro", ("jr w pro",)),
    _m("dvF1W0A000", "daVinciAW10", "3F1AWP", "dvF1W0A000_V2", _V5, "YYYnYnY", (200, 200, 200),
       "da Vinci 1.0 Pro", ("pro",)),
    _m("dvF1WSA000", "daVinciAS10", "3F1ASP", "dvF1WSA000_V2", _V5, "YYYnYYY", (200, 200, 190),
       "da Vinci 1.0 Pro 3in1", ("pro 3in1",)),
    _m("dv1SW0A000", "dv1SW0A000", "3F1SWP", "dv1SW0A000_V2", _V5, "YYYnYnY", (300, 300, 300), "da Vinci Super",
       ("super",), "0.4/0.6/0.8 mm nozzles"),
)

DEFAULT_MODEL_NUMBER = "dv1MX0A000"
"""miniMaker: what a conversion targets when nothing else is known (miniMover's choice too)."""


def _key(text: str) -> str:
    """Fold a user-typed name: case, punctuation, spacing and the 'da Vinci' prefix do not matter."""
    folded = re.sub(r"[^0-9a-z+]", "", text.lower().replace("+", "plus"))
    return folded.removeprefix("davinci")


def _index() -> dict[str, PrinterModel]:
    index: dict[str, PrinterModel] = {}
    for model in MODELS:  # aliases first so a real name or number always wins a clash
        for alias in model.aliases:
            index.setdefault(_key(alias), model)
    for model in MODELS:
        index[_key(model.name)] = model
    for model in MODELS:
        index[model.model_number.lower()] = model
    return index


_INDEX = _index()


def find_model(text: str) -> PrinterModel:
    """The model named by a model number (`p:`), a name or a common alias, in any case.

    An unknown one is an InputError of one short line: the text shortened, the closest names (difflib), and a few
    known names rather than all of them."""
    cleaned = text.strip()
    model = (_INDEX.get(cleaned.lower()) or _INDEX.get(_key(cleaned))) if cleaned else None
    if model is None:
        raise InputError(f"unknown printer model {excerpt(text, 40)}{_nearest(cleaned)}")
    return model


def _nearest(text: str) -> str:
    """` (did you mean 'miniMaker'?)` for the name closest to `text`, else a few known names to go by."""
    import difflib

    names = {_key(m.name): m.name.removeprefix("da Vinci ") for m in MODELS}
    names |= {m.model_number.lower(): m.model_number for m in MODELS}
    close = difflib.get_close_matches(_key(text[:100]) or text[:100].lower(), list(names), n=1, cutoff=0.7)
    if close:
        return f" (did you mean {names[close[0]]!r}?)"
    return (f"; give a model number or name such as {DEFAULT_MODEL_NUMBER}, miniMaker, mini w, nano, Jr. 1.0 Pro "
            f"or Super ({len(MODELS)} models are known)")


def simulated_model(text: str) -> PrinterModel:
    """The model `text` names, if it speaks XYZv3 (so the simulator can be it); an InputError otherwise."""
    model = find_model(text)
    if not model.v3_protocol:
        raise InputError(f"{model.name} ({model.model_number}) does not speak XYZv3; it cannot be simulated here")
    return model


def models_for_file_id(file_id: str) -> tuple[PrinterModel, ...]:
    """Every model whose .3w carries this `; machine =` value (several share one, e.g. `daVinciF10`)."""
    wanted = file_id.strip().lower()
    return tuple(model for model in MODELS if model.file_id.lower() == wanted)


def model_for_file_id(file_id: str, prefer: PrinterModel | None = None) -> PrinterModel | None:
    """The model a .3w's `; machine =` value names.

    The value is a file id (miniMover's fileNum), so file ids decide first: `dv1JSOA000` (letter O) is the
    Jr. 1.0 3in1's file id even though it is also the Open-filament 3in1's model number. Among models sharing the
    id, `prefer` (e.g. the connected printer) wins, else the first in the table. A value that is no file id but a
    model number (as some hand-made converters write) names that model."""
    sharing = models_for_file_id(file_id)
    if sharing:
        return prefer if prefer in sharing else sharing[0]
    wanted = file_id.strip().lower()
    for model in MODELS:
        if model.model_number.lower() == wanted:
            return model
    return None


def default_model() -> PrinterModel:
    return find_model(DEFAULT_MODEL_NUMBER)
