"""Named devices: an optional TOML file mapping names to a device kind, an address and options.

    [devices.office]
    kind = "xyz"
    url = "192.168.1.50"
    default = true          # used when -d is not given
    model = "miniMaker"     # any other key is an option for that device

Location: $FABWIRE_CONFIG, else $XDG_CONFIG_HOME/fabwire/devices.toml (~/.config/fabwire/devices.toml).
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from fabwire.devices import KINDS, DeviceKind
from fabwire.errors import ConfigError
from fabwire.transport.urls import Endpoint, parse_url

OptionValue = str | int | float | bool
CONFIG_ENV = "FABWIRE_CONFIG"


@dataclass(frozen=True, slots=True)
class NamedDevice:
    name: str
    kind: DeviceKind
    endpoint: Endpoint
    default: bool = False
    options: dict[str, OptionValue] = field(default_factory=dict)


def config_path() -> Path:
    if override := os.environ.get(CONFIG_ENV):
        return Path(override)
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "fabwire" / "devices.toml"


def _line_of(text: str, name: str) -> int:
    pattern = re.compile(rf"^[ \t]*\[[ \t]*devices[ \t]*\.[ \t]*\"?{re.escape(name)}\"?\s*\]", re.MULTILINE)
    match = pattern.search(text)
    return text.count("\n", 0, match.start()) + 1 if match else 0


def _parse_device(path: Path, text: str, name: str, table: object) -> NamedDevice:
    line = _line_of(text, name)
    where = f"{path}, line {line}" if line else str(path)

    def fail(problem: str) -> ConfigError:
        return ConfigError(f"{where}: device {name!r}: {problem}")

    if not isinstance(table, dict):
        raise fail("must be a table like [devices.NAME]")
    kind_name = table.get("kind")
    if not isinstance(kind_name, str) or kind_name not in KINDS:
        raise fail(f"'kind' must be one of {', '.join(KINDS)} (got {kind_name!r})")
    kind = KINDS[kind_name]
    url = table.get("url")
    if not isinstance(url, str):
        raise fail("'url' must be a string such as \"192.168.1.50\" or \"/dev/ttyACM0\"")
    try:
        endpoint = parse_url(url, kind)
    except Exception as exc:
        raise fail(str(exc)) from None
    default = table.get("default", False)
    if not isinstance(default, bool):
        raise fail("'default' must be true or false")
    options: dict[str, OptionValue] = {}
    for key, value in table.items():
        if key in ("kind", "url", "default"):
            continue
        if not isinstance(value, str | int | float | bool):
            raise fail(f"option {key!r} must be a string, number or boolean")
        options[key] = value
    return NamedDevice(name, kind, endpoint, default, options)


def load_devices(path: Path | None = None) -> dict[str, NamedDevice]:
    """Read the config file; a missing file means no named devices, a malformed one is a ConfigError."""
    path = path or config_path()
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return {}
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read config file {path}: {exc}") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    unknown = set(data) - {"devices"}
    if unknown:
        raise ConfigError(f"{path}: unknown top-level key(s) {', '.join(sorted(unknown))}; expected [devices.NAME]")
    devices = data.get("devices", {})
    if not isinstance(devices, dict):
        raise ConfigError(f"{path}: 'devices' must be a table of [devices.NAME] sections")
    return {name: _parse_device(path, text, name, table) for name, table in devices.items()}


@dataclass(frozen=True, slots=True)
class Target:
    """Where a command goes: the address, and the options a named device carries."""

    endpoint: Endpoint
    name: str = ""
    options: dict[str, OptionValue] = field(default_factory=dict)


def resolve_target(device: str | None, kind: DeviceKind, path: Path | None = None) -> Target:
    """A -d value may name a configured device or be an address; no -d picks the kind's default device."""
    if device is not None and ("/" in device or ":" in device):
        return Target(parse_url(device, kind))
    devices = load_devices(path)
    if device is None:
        mine = [d for d in devices.values() if d.kind is kind]
        chosen = [d for d in mine if d.default] or (mine if len(mine) == 1 else [])
        if len(chosen) != 1:
            raise ConfigError(
                f"no {kind.title} given: pass -d ADDRESS (or a name from {path or config_path()}), "
                f"e.g. -d sim://{kind.name}"
            )
        found = chosen[0]
    elif device in devices:
        found = devices[device]
        if found.kind is not kind:
            raise ConfigError(f"device {device!r} is a {found.kind.title}, not a {kind.title}")
    else:
        return Target(parse_url(device, kind))
    return Target(found.endpoint, found.name, dict(found.options))
