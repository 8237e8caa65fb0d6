"""`fabwire devices list|show|add|remove`: the named devices in devices.toml.

Edits keep the rest of the file as the user wrote it (comments, order): `add` appends a section, `remove` cuts one,
and the result is validated by the schema before it replaces the file.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
import tomllib
from pathlib import Path
from typing import Any, get_origin, get_type_hints

import click
import msgspec

from fabwire.checks import ASCII_BLANKS, refuse
from fabwire.cli_options import device_names
from fabwire.cli_support import App, pass_app
from fabwire.config import (
    SCHEMAS,
    NamedDevice,
    check_device_name,
    config_path,
    load_devices,
    parse_devices,
    read_config_text,
    section_lines,
    validate_settings,
)
from fabwire.devices import KINDS
from fabwire.errors import ConfigError, InputError, closest, excerpt, nearest
from fabwire.transport.sameness import machines_of, same_machine
from fabwire.transport.urls import parse_url

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
_ARGUMENTS = {"kind": "--kind", "url": "the ADDRESS argument", "default": "--default"}
"""What `devices add` takes as its own arguments and options, never with --set: how it is given instead."""


def _toml_key(name: str) -> str:
    return name if _BARE_KEY.match(name) else json.dumps(name)


def _toml_value(value: Any) -> str:
    """A scalar or list of the schema's types as TOML (JSON's string escapes are TOML's too)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return json.dumps(str(value), ensure_ascii=False)


def _parse_setting(text: str, lists: frozenset[str]) -> tuple[str, Any]:
    """KEY=VALUE as the key and a TOML value (a plain word is text); for a key in `lists`, a VALUE not written
    as a TOML list is the comma-separated items: `accept=3.0.3,3.0.4` is `accept = ["3.0.3", "3.0.4"]`."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise refuse("set-form", text=excerpt(text, 40))
    if key in lists and not raw.lstrip().startswith("["):
        return key, [item.strip() for item in raw.split(",") if item.strip()]
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except (tomllib.TOMLDecodeError, RecursionError, ValueError):
        value = raw.strip()  # a plain word: a string
    return key, value


def _write(path: Path, text: str) -> None:
    """Validate, then replace the file atomically (a crash leaves the old or the new file, never half)."""
    parse_devices(text, path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".devices-", suffix=".toml", dir=path.parent)
    except OSError as exc:
        raise ConfigError(f"cannot write the config file {path}: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as stream:
            stream.write(text)
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise ConfigError(f"cannot write the config file {path}: {exc.strerror or exc}") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _row(device: NamedDevice) -> dict[str, Any]:
    return {"name": device.name, "kind": device.kind.name, "url": device.settings.url, "default": device.default}


def _find(devices: dict[str, NamedDevice], name: str, path: Path) -> NamedDevice:
    if name not in devices:
        raise ConfigError(f"no device named {excerpt(name, 64)} in {path}{closest(name, devices)}")
    return devices[name]


@click.group()
def devices() -> None:
    """Named devices (devices.toml): -d NAME uses one, and its settings apply to every command."""


@devices.command("list")
@pass_app
def list_cmd(app: App) -> None:
    """List the configured devices."""
    path = config_path()
    found = load_devices(path)
    rows = [_row(d) for d in found.values()]

    def human() -> None:
        if not rows:
            app.output.out.print(f"no devices configured (add one with `fabwire devices add`; file {path})")
            return
        width = max(len(r["name"]) for r in rows)
        for r in rows:
            mark = "  (default)" if r["default"] else ""
            app.output.out.print(f"{r['name']:<{width}}  {r['kind']:<6}  {r['url']}{mark}")

    app.output.result(rows, human)


@devices.command("show")
@click.argument("name", shell_complete=device_names)
@pass_app
def show(app: App, name: str) -> None:
    """Show every setting of device NAME as TOML: a setting at its default value says `# default`, a setting
    without a value is a comment."""
    path = config_path()
    device = _find(load_devices(path), name, path)
    settings = msgspec.to_builtins(device.settings)
    first = {"name": name, "kind": device.kind.name, "url": settings.pop("url"), "default": settings.pop("default")}
    data = {**first, **settings}
    defaults = {f.encode_name: msgspec.to_builtins(f.default) for f in msgspec.structs.fields(device.settings)
                if f.default is not msgspec.NODEFAULT}
    lines = [f"# {key}: not set" if value is None
             else f"{key} = {_toml_value(value)}" + ("  # default" if defaults.get(key, ...) == value else "")
             for key, value in data.items() if key != "name"]
    app.output.result(data, "\n".join([f"[devices.{_toml_key(name)}]", *lines]))


@devices.command("add")
@click.argument("name")
@click.argument("url")
@click.option("--kind", "kind_name", required=True, type=click.Choice(sorted(KINDS)), help="The device kind.")
@click.option("--default", "is_default", is_flag=True, help="Use it when -d is not given.")
@click.option("--set", "settings", multiple=True, metavar="KEY=VALUE",
              help="A setting of the kind, e.g. speed=50 or link=wifi (repeat); a list setting takes its items "
                   "separated by commas, e.g. accept=3.0.3,3.0.4.")
@pass_app
def add(app: App, name: str, url: str, kind_name: str, is_default: bool, settings: tuple[str, ...]) -> None:
    """Name the device at URL (any address -d takes), with its settings.

    NAME is 1 to 64 letters, digits, '.', '_' and '-', starting with a letter or digit. Every check -d and
    `fabwire serve` make of the address and the settings is made here, before the file is touched."""
    for given in (name, url, *settings):
        try:
            given.encode("utf-8")
        except UnicodeEncodeError:  # bytes that are not UTF-8 arrive as lone surrogates
            raise InputError(f"{excerpt(given, 40)} is not valid text (the config file is UTF-8)") from None
    check_device_name(name)
    path = config_path()
    text = read_config_text(path)
    existing = parse_devices(text, path) if text else {}
    if name in existing:
        raise ConfigError(f"{path} already has a device named {name!r}: remove it first")
    kind = KINDS[kind_name]
    values: dict[str, Any] = {"kind": kind_name, "url": url.strip(ASCII_BLANKS)}  # as parse_url reads it
    if is_default:
        values["default"] = True
    schema = SCHEMAS[kind_name]
    lists = frozenset(k for k, hint in get_type_hints(schema).items() if get_origin(hint) is list)
    settable = [f for f in schema.__struct_fields__ if f not in _ARGUMENTS]  # no hint at what --set refuses
    for item in settings:
        key, value = _parse_setting(item, lists)
        if key in _ARGUMENTS:
            raise refuse("set-reserved", key=key)
        if key not in settable:
            hint = closest(key, settable)
            argument = None if hint else nearest(key, _ARGUMENTS)
            raise refuse("set-unknown", title=kind.title, key=excerpt(key, 40),
                         hint=hint or (f" (give {argument} with {_ARGUMENTS[argument]})" if argument else ""))
        if isinstance(value, str) and not value.isprintable():
            raise refuse("set-control", key=key, value=excerpt(value, 40))
        values[key] = value
    validate_settings(kind, {k: v for k, v in values.items() if k != "kind"}, what="setting")
    endpoint = parse_url(url, kind)  # the address as -d reads it: refused here, before the file is touched
    if kind_name == "xyz" and isinstance(values.get("model"), str):
        from fabwire.xyz.models import find_model

        try:
            find_model(values["model"])  # a model the printer table does not know would only fail at print time
        except InputError as exc:
            raise refuse("set-model", problem=str(exc)) from None
    kin = [other for other in existing.values() if other.kind is kind]
    for other in kin:
        if is_default and other.default:
            raise ConfigError(f"{other.name!r} is the default {kind.title} already: add {name!r} without --default, "
                              f"then `fabwire devices default {name}`")
    # `fabwire serve` monitors each machine once (`agent.command.one_each`), however its address is spelt
    mine, *theirs = machines_of([endpoint, *(other.endpoint for other in kin)])
    same = same_machine(mine, [(other.name, keys) for other, keys in zip(kin, theirs, strict=True)])
    if same is not None:
        raise InputError(f"{excerpt(url, 60)} is the machine {same!r} names already "
                         f"({existing[same].endpoint.url}): one machine has one name")
    section = f"[devices.{_toml_key(name)}]\n" + "".join(f"{k} = {_toml_value(v)}\n" for k, v in values.items())
    separator = "" if not text or text.endswith("\n\n") else "\n" if text.endswith("\n") else "\n\n"
    _write(path, text + separator + section)
    app.output.result({"added": name, "file": str(path)}, f"added {name} to {path}")


_DEFAULT_LINE = re.compile(r"[ \t]*default[ \t]*=")


def _section_span(lines: list[str], header: int) -> range:
    """The line indexes of the keys of the section whose header is on (1-based) line `header`."""
    end = header
    while end < len(lines) and not lines[end].lstrip().startswith("["):
        end += 1
    return range(header, end)


@devices.command("default")
@click.argument("name", shell_complete=device_names)
@pass_app
def default_cmd(app: App, name: str) -> None:
    """Make device NAME the one of its kind used when -d is not given (the default it replaces is kept as a named
    device; the rest of the file stays as it is)."""
    path = config_path()
    text = read_config_text(path)
    found = parse_devices(text, path) if text else {}
    chosen = _find(found, name, path)
    before = [other.name for other in found.values() if other.kind is chosen.kind and other.default]
    if before == [name]:
        app.output.result({"default": name, "kind": chosen.kind.name, "file": str(path), "changed": False},
                          f"{name} is the default {chosen.kind.title} already")
        return
    headers = section_lines(text)
    missing = [n for n in {name, *before} if n not in headers]
    if missing:
        raise ConfigError(f"{excerpt(missing[0], 64)} is not written as a [devices.NAME] section in {path}: "
                          "edit the file by hand")
    lines = text.splitlines(keepends=True)
    drop = {i for other in before for i in _section_span(lines, headers[other]) if _DEFAULT_LINE.match(lines[i])}
    own = [i for i in _section_span(lines, headers[name]) if _DEFAULT_LINE.match(lines[i])]
    edited = []
    for i, line in enumerate(lines):
        if i in drop:
            continue
        if i in own:
            line = "default = true\n"
        edited.append(line)
        if i == headers[name] - 1 and not own:
            edited.append("default = true\n")
    new_text = "".join(edited)
    after = parse_devices(new_text, path)
    if [d.name for d in after.values() if d.kind is chosen.kind and d.default] != [name]:
        raise ConfigError(f"the defaults in {path} are not written as plain `default = …` lines: edit the file "
                          "by hand")
    _write(path, new_text)
    was = f" (was {', '.join(before)})" if before else ""
    app.output.result({"default": name, "kind": chosen.kind.name, "file": str(path), "changed": True,
                       "was": before}, f"{name} is now the default {chosen.kind.title}{was}")


@devices.command("remove")
@click.argument("name", shell_complete=device_names)
@pass_app
def remove(app: App, name: str) -> None:
    """Forget device NAME (the rest of the file stays as it is)."""
    path = config_path()
    text = read_config_text(path)
    headers = section_lines(text)
    if name not in headers:  # a section being removed may be the broken one: only an absent name is looked up
        _find(parse_devices(text, path) if text else {}, name, path)
    lines = text.splitlines(keepends=True)
    if name not in headers:
        raise ConfigError(f"{excerpt(name, 64)} is not written as a [devices.NAME] section in {path}: "
                          "edit the file by hand")
    start = headers[name] - 1
    end = _section_span(lines, headers[name]).stop
    while end < len(lines) and end > start + 1 and lines[end - 1].lstrip().startswith(("#", "\n")):
        end -= 1  # comments just above the next section belong to it
    _write(path, "".join(lines[:start] + lines[end:]))
    app.output.result({"removed": name, "file": str(path)}, f"removed {name} from {path}")
