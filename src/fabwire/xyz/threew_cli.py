"""`fabwire xyz convert` and `fabwire xyz info`: .3w files on disk, no printer needed."""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

import click

from fabwire import units
from fabwire.cli_support import App
from fabwire.errors import InputError
from fabwire.xyz import intake
from fabwire.xyz.gcodeinfo import GcodeMetadata, finish
from fabwire.xyz.models import PrinterModel, find_model
from fabwire.xyz.threew import (
    Progress as ProgressCallback,
)
from fabwire.xyz.threew import (
    ThreeWInfo,
    convert_3w_to_gcode,
    convert_gcode_file,
    inspect_3w,
)

BAR_THRESHOLD = 8 << 20
"""Files at least this large get a progress bar (where rich draws one: on a terminal)."""


def _app(ctx: click.Context) -> App:
    return ctx.find_object(App) or App()


@contextlib.contextmanager
def _progress(app: App, label: str, size: int) -> Iterator[ProgressCallback | None]:
    if size < BAR_THRESHOLD or not app.output.lines_err().is_terminal:  # off a terminal the bar is never drawn
        yield None
        return
    from rich.progress import BarColumn, DownloadColumn, Progress, TextColumn, TimeRemainingColumn, TransferSpeedColumn

    columns = (TextColumn("{task.description}"), BarColumn(), DownloadColumn(), TransferSpeedColumn(),
               TimeRemainingColumn())
    with Progress(*columns, console=app.output.err, transient=True) as bar:
        task = bar.add_task(label, total=size)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


def _model_data(model: PrinterModel | None) -> dict[str, Any] | None:
    if model is None:
        return None
    return {"model_number": model.model_number, "name": model.name, "file_id": model.file_id,
            "file_format": model.file_format.value}


def _info_data(info: ThreeWInfo) -> dict[str, Any]:
    return {
        "variant": info.variant, "container": info.container, "tag": info.tag, "zipped": info.zipped,
        "header_encrypted": info.header_encrypted, "body_encrypted": info.body_encrypted,
        "gap_bytes": info.gap, "header_offset_bytes": info.header_offset, "header_bytes": len(info.header),
        "crc_stored": f"{info.crc_stored:08x}", "crc_computed": f"{info.crc_computed:08x}", "crc_ok": info.crc_ok,
        "pad_ok": info.pad_ok, "machine": info.machine, "model": _model_data(info.model),
        "print_time_s": info.print_time_s, "filament_mm": info.filament_mm, "layers": info.layers,
        "gcode_bytes": info.gcode_size, "body_bytes": info.body_size, "fields": info.fields,
    }


def metadata_summary(info: ThreeWInfo) -> str:
    return (f"print time {units.duration(info.print_time_s)}, filament {units.filament(info.filament_mm)}, "
            f"{units.count(info.layers, 'layer')}")


def _warn_crc(app: App, name: Path, info: ThreeWInfo) -> None:
    if not info.crc_ok:
        app.output.note(f"warning: {name}: CRC mismatch (stored {info.crc_stored:08x}, computed "
                        f"{info.crc_computed:08x}); the file may be damaged")


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror}") from exc


@click.command("convert")
@click.argument("src", type=click.Path(dir_okay=False, path_type=Path, allow_dash=True))
@click.argument("dst", type=click.Path(dir_okay=False, path_type=Path), required=False)
@click.option("-m", "--model", "model_text", metavar="MODEL",
              help="Target printer for a .3w: model number, name or alias (default: miniMaker, or the source "
                   ".3w's own model when re-targeting).")
@click.option("--format", "file_format", type=click.Choice(["v2", "v5"]),
              help="Container version (default: what the model needs; nano on firmware 3.x wants v5).")
@click.option("--zip/--no-zip", "zipped", default=None, help="Zipped AES-128 body (1.0/1.1/2.0 generation) or not.")
@click.option("--repair", is_flag=True, help="Drop NUL bytes found inside the G-code (and say on which lines) "
                                             "instead of refusing the file.")
@click.option("--force", is_flag=True, help="Convert even when the extrusions reach beyond the model's build volume.")
@click.option("--keep-arcs", is_flag=True, help="Pass G2/G3 arcs through (default: line segments within 0.01 mm; "
                                                "no public source shows da Vinci firmware running arcs).")
@click.pass_context
def convert(ctx: click.Context, src: Path, dst: Path | None, model_text: str | None, file_format: str | None,
            zipped: bool | None, repair: bool, force: bool, keep_arcs: bool) -> None:
    """Convert G-code to a .3w print file or back; the direction follows the files' types ('-' reads SRC from
    standard input). Without DST, SRC's name with the other type's suffix (part.gcode → part.3w), when no such
    file exists.

    A .3w source with a .3w destination is re-targeted (e.g. for another model or format).
    """
    app = _app(ctx)
    container: Literal[2, 5] | None = None if file_format is None else (5 if file_format == "v5" else 2)
    if dst is None and str(src) == intake.STDIN:
        raise click.UsageError("give DST when SRC is standard input ('-')")
    with intake.input_file(src) as (path, shown):
        kind, head = intake.sniff(path, shown)
        intake.require_printable(kind, shown, head)
        replace = dst is not None  # an output not named is never put in place of a file (it may be the source)
        if dst is None:
            dst = src.with_suffix(".gcode" if kind.decoded is intake.Kind.THREEW else ".3w")
            try:
                taken = dst.exists() or dst.is_symlink()
            except OSError as exc:  # a name too long for the file system
                raise InputError(f"cannot write {dst}: {exc.strerror or exc}") from None
            if taken:
                raise InputError(f"{dst} exists already: name it as DST to replace it, or give another DST")
        writing = dst.suffix.lower() == ".3w"
        with intake.decoded_path(path, kind) as plain:
            _convert(app, Path(shown), plain, kind.decoded, dst, writing, model_text, container, zipped,
                     {"repair": repair, "force": force, "keep_arcs": keep_arcs, "replace": replace})


def _convert(app: App, src: Path, plain: Path, kind: intake.Kind, dst: Path, writing: bool, model_text: str | None,
             container: Literal[2, 5] | None, zipped: bool | None, options: dict[str, bool] | None = None) -> None:
    """Convert `plain` (the source with any base64 layer decoded) of `kind` THREEW or GCODE."""
    size = _size(plain)
    if kind is intake.Kind.THREEW:
        if not writing:
            if model_text or container or zipped is not None:
                raise InputError("--model, --format and --zip only apply when writing a .3w file")
            with _progress(app, f"decoding {src.name}", size) as progress:
                info = convert_3w_to_gcode(plain, dst, progress, replace=(options or {}).get("replace", True))
            _warn_crc(app, src, info)
            _report(app, "3w-to-gcode", src, dst, info)
            return
        source_info = inspect_3w(plain)
        _warn_crc(app, src, source_info)
        model = find_model(model_text) if model_text else source_info.model
        if model is None:
            raise InputError(f"{src} names no known model (machine {source_info.machine!r}); give --model")
        with tempfile.TemporaryDirectory(dir=dst.parent if dst.parent.is_dir() else None) as scratch:
            middle = Path(scratch) / "source.gcode"
            with _progress(app, f"decoding {src.name}", size) as progress:
                convert_3w_to_gcode(plain, middle, progress)
            with _progress(app, f"encoding {dst.name}", _size(middle)) as progress:
                info = convert_gcode_file(middle, dst, model, container=container, zipped=zipped, progress=progress,
                                          **(options or {}))
        _report(app, "3w-to-3w", src, dst, info)
        return
    if not writing:
        raise InputError(f"{src} is G-code and {dst} is not a .3w file: nothing to convert "
                         "(name the output *.3w to make a print file)")
    model = find_model(model_text or "dv1MX0A000")
    with _progress(app, f"encoding {dst.name}", size) as progress:
        info = convert_gcode_file(plain, dst, model, container=container, zipped=zipped, progress=progress,
                                  **(options or {}))
    _report(app, "gcode-to-3w", src, dst, info)


def _report(app: App, direction: str, src: Path, dst: Path, info: ThreeWInfo) -> None:
    data = {"direction": direction, "source": str(src), "output": str(dst), "written_bytes": _size(dst),
            **_info_data(info), "notes": list(info.notes)}
    for note in info.notes:
        app.output.note(f"note: {note}")
    model = info.model.name if info.model else info.machine or "unknown model"
    if direction == "3w-to-gcode":
        text = f"wrote {dst} ({info.gcode_size} bytes of G-code) from a {info.variant} file for {model}; "
    else:
        text = f"wrote {dst} for {model} ({info.variant}, {data['written_bytes']} bytes); "
    app.output.result(data, text + metadata_summary(info))


@click.command("info")
@click.argument("file", type=click.Path(dir_okay=False, path_type=Path, allow_dash=True))
@click.pass_context
def info(ctx: click.Context, file: Path) -> None:
    """Show what a .3w file holds (variant, CRC, model, print metadata), or what a G-code file would give ('-'
    reads standard input)."""
    app = _app(ctx)
    with intake.input_file(file) as (path, shown):
        file = Path(shown)
        size = _size(path)
        kind, head = intake.sniff(path, shown)
        intake.require_printable(kind, shown, head)
        with intake.decoded_path(path, kind) as plain:
            if kind.decoded is intake.Kind.GCODE:
                _gcode_info(app, plain, file)
                return
            with _progress(app, f"checking {file.name}", size) as progress:
                details = inspect_3w(plain, progress)
    data = {"file": str(file), "size_bytes": size, **_info_data(details)}

    def human() -> None:
        from rich.table import Table

        table = Table(show_header=False, box=None)
        table.add_column(style="bold")
        table.add_column()
        model = details.model
        table.add_row("file", f"{file} ({size} bytes)")
        table.add_row("variant", details.variant)
        table.add_row("header", f"{'AES-128-CBC' if details.header_encrypted else 'plaintext'}, "
                                f"{len(details.header)} bytes at {details.header_offset} (gap {details.gap})")
        table.add_row("body", f"{details.body_size} bytes, {'encrypted' if details.body_encrypted else 'plaintext'}"
                              f"{'' if details.pad_ok else ', no final pad'}; {details.gcode_size} bytes of G-code")
        crc = "ok" if details.crc_ok else f"MISMATCH (computed {details.crc_computed:08x})"
        table.add_row("crc", f"{details.crc_stored:08x} {crc}")
        table.add_row("model", f"{model.name} ({model.model_number})" if model
                      else f"unknown (machine {details.machine!r})")
        table.add_row("print time", units.duration(details.print_time_s))
        table.add_row("filament", "?" if details.filament_mm is None else units.filament(details.filament_mm))
        table.add_row("layers", str(details.layers) if details.layers is not None else "?")
        for key, value in details.fields.items():
            if key not in {"print_time", "total_filament", "total_layers", "machine"}:
                table.add_row(key, value)
        app.output.out.print(table)

    app.output.result(data, human)


def _gcode_info(app: App, plain: Path, file: Path) -> None:
    stated, computed = intake.gcode_metadata(plain)
    final: GcodeMetadata = finish(stated, computed)

    def source(value: object) -> str:
        return "stated" if value is not None else "computed" if computed is not None else "default"

    sources = {"print_time_s": source(stated.print_time_s), "filament_mm": source(stated.filament_mm),
               "layers": source(stated.layers)}
    data = {"file": str(file), "kind": "gcode", "slicer": stated.slicer, "print_time_s": final.print_time_s,
            "filament_mm": final.filament_mm, "layers": final.layers, "sources": sources,
            "notes": list(stated.notes)}
    notes = "".join(f"\n{note}" for note in stated.notes)
    app.output.result(data, f"{file}: G-code from {stated.slicer or 'an unknown slicer'}; print time "
                            f"{units.duration(final.print_time_s)} ({sources['print_time_s']}), filament "
                            f"{units.filament(final.filament_mm)} ({sources['filament_mm']}), "
                            f"{units.count(final.layers, 'layer')} ({sources['layers']}){notes}")
