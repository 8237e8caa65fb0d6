"""Named devices: `devices.toml`, validated by a typed schema, maps names to a device kind, an address and settings.

    [devices.office]
    kind = "xyz"              # xyz | lineus | mmu
    url = "192.168.1.50"      # any address -d takes
    default = true            # used when -d is not given (at most one per kind)
    link = "wifi"             # any setting of that kind (see XYZSettings, LineUsSettings, MMUSettings)

Location: $FABWIRE_CONFIG, else the platform's config directory (platformdirs), e.g. ~/.config/fabwire/devices.toml.
Every command and `X.open` apply a device's settings; options given explicitly win over the file. A file with a
problem is a ConfigError for what needs it (a name, the default device) and only a ConfigWarning when the target is an
address (see `resolve_target`).
"""

from __future__ import annotations

import ipaddress
import os
import re
import warnings
from pathlib import Path
from typing import Annotated, Any, Literal, get_args, get_type_hints

import msgspec

from fabwire.checks import MAX_NAME, NUMERIC_HOST, refuse
from fabwire.devices import KINDS, DeviceKind
from fabwire.errors import ConfigError, ConfigWarning, InputError, closest, excerpt
from fabwire.files import read_bounded
from fabwire.transport.urls import WINDOWS_PORT, Endpoint, parse_url

CONFIG_ENV = "FABWIRE_CONFIG"
MAX_DEVICES = 10_000
"""A file with more devices than this is refused rather than parsed (a config, not a database)."""
MAX_CONFIG_BYTES = 4 << 20
"""A larger config file (or an endless one such as /dev/zero) is refused after reading this much."""

Seconds = Annotated[float, msgspec.Meta(gt=0, le=86_400)]


class DeviceSettings(msgspec.Struct, kw_only=True, forbid_unknown_fields=True, tag_field="kind"):
    """Fields every device entry has."""

    url: str = ""
    """The device's address (required in the file; absent when `open` is given an address)."""
    default: bool = False
    timeout: Seconds = 5.0
    """Seconds to wait for the link to open."""


class XYZSettings(DeviceSettings, tag="xyz"):
    link: Literal["auto", "serial", "wifi"] = "auto"
    """Reply framing: auto = Wi-Fi on TCP, serial otherwise."""
    reply_timeout: Seconds | None = None
    """Seconds to wait for each reply (default: the link timeout, at least 2 s)."""
    model: str | None = None
    """Model to convert G-code for when printing (default: the printer's own)."""


class LineUsSettings(DeviceSettings, tag="lineus"):
    lookahead: bool = False
    """Keep up to three commands in flight (firmware 3 only) for smoother motion."""
    hello_timeout: Seconds | None = None
    """Seconds to wait for the greeting (default: the link timeout, at least 2 s)."""
    reply_timeout: Seconds = 5.0


class MMUSettings(DeviceSettings, tag="mmu"):
    speed: Annotated[float, msgspec.Meta(ge=0.01, le=10_000)] = 1.0
    """The MMU runs this many times faster than real time (a simulator's --speed): 0.01 to 10 000, as `--speed`
    takes it (`fabwire.simspeed`); slower would stretch every timeout past any wait a user makes."""
    accept: list[Annotated[str, msgspec.Meta(pattern=r"^\d{1,3}\.\d{1,3}\.\d{1,3}\Z",
                                             examples=["3.0.3"])]] = []
    """Firmware versions to accept, e.g. ["3.0.3"] (default: every supported one)."""
    connect_timeout: Seconds | None = None
    """Seconds for the handshake (default: 30 s of MMU time)."""
    auto_retries: Annotated[int, msgspec.Meta(ge=0, le=100)] = 3


AnySettings = XYZSettings | LineUsSettings | MMUSettings
SCHEMAS: dict[str, type[AnySettings]] = {"xyz": XYZSettings, "lineus": LineUsSettings, "mmu": MMUSettings}
OptionValue = str | int | float | bool | list[str]


class NamedDevice(msgspec.Struct, frozen=True):
    name: str
    kind: DeviceKind
    endpoint: Endpoint
    settings: AnySettings
    line: int = 0

    @property
    def default(self) -> bool:
        return self.settings.default

    @property
    def options(self) -> dict[str, Any]:
        """The settings this entry gives beyond url/default/kind."""
        return explicit_settings(self.settings)


def explicit_settings(settings: AnySettings) -> dict[str, Any]:
    """Fields that differ from the schema's defaults, without url/default."""
    blank = type(settings)()
    return {f: getattr(settings, f) for f in settings.__struct_fields__
            if f not in ("url", "default") and getattr(settings, f) != getattr(blank, f)}


def config_path() -> Path:
    if override := os.environ.get(CONFIG_ENV):
        return Path(override)
    from platformdirs import user_config_path

    return user_config_path("fabwire", appauthor=False) / "devices.toml"


def state_path() -> Path:
    """Where fabwire keeps state between runs (drawing progress, the agent's history): the platform's state folder,
    e.g. ~/.local/state/fabwire (honouring $XDG_STATE_HOME) on Linux."""
    from platformdirs import user_state_path

    return user_state_path("fabwire", appauthor=False)


_HEADER = re.compile(r"""^[ \t]*\[[ \t]*devices[ \t]*\.[ \t]*(?:"([^"\n]*)"|'([^'\n]*)'|([A-Za-z0-9_-]+))[ \t]*\]""",
                     re.MULTILINE)


def section_lines(text: str) -> dict[str, int]:
    """Line number of each `[devices.NAME]` header, found in one pass over the text."""
    lines: dict[str, int] = {}
    line, pos = 1, 0
    for match in _HEADER.finditer(text):
        line += text.count("\n", pos, match.start())
        pos = match.start()
        lines.setdefault(match.group(1) or match.group(2) or match.group(3) or "", line)
    return lines


def _key_line(text: str, name: str, key: str | None, header: int) -> int:
    """The line where device `name` writes `key`: its `key = …` line in the [devices.NAME] section starting at line
    `header`, else a dotted `NAME.key = …` or the `NAME = {…}` inline table that holds it; `header` (0 when the
    entry has no section header) when the key is not written at all (a missing `url`)."""
    lines = text.splitlines()
    if key is not None and header:
        pattern = re.compile(rf"[ \t]*{_written(key)}[ \t]*=")
        for number in range(header, len(lines)):  # header is 1-based: this starts on the line after it
            if lines[number].lstrip().startswith("["):
                break
            if pattern.match(lines[number]):
                return number + 1
        return header
    prefix = rf"[ \t]*(?:devices[ \t]*\.[ \t]*)?{_written(name)}[ \t]*"
    shapes = [re.compile(rf"{prefix}\.[ \t]*{_written(key)}[ \t]*=")] if key is not None else []
    for shape in [*shapes, re.compile(rf"{prefix}=")]:
        for number, line in enumerate(lines, 1):
            if shape.match(line):
                return number
    return header


def _written(word: str) -> str:
    """A TOML key as a regex: bare, "quoted" or 'literal'."""
    return rf"""(?:{re.escape(word)}|"{re.escape(word)}"|'{re.escape(word)}')"""


def _problem_key(error: msgspec.ValidationError) -> str | None:
    """The top-level key a msgspec error is about (`accept` for `$.accept[0]`), or None."""
    message = str(error)
    unknown = re.match(r"Object contains unknown field `([^`]*)`", message)
    if unknown:
        return unknown.group(1)
    where = re.search(r" - at `\$\.([A-Za-z0-9_]+)", message)
    return where.group(1) if where else None


def _example(schema: type[AnySettings], key: str) -> str:
    """` (such as '3.0.3')` from the field's msgspec.Meta examples, or nothing."""
    for meta in re.findall(r"examples=\[([^\]]*)\]", repr(get_type_hints(schema, include_extras=True).get(key))):
        return f" (such as {meta.split(',')[0]})"
    return ""


_TYPE_WORDS = {"float": "a number", "int": "a whole number", "str": "text", "bool": "true or false",
               "array": "a list", "object": "a table", "null": "nothing"}
_BOUND_WORDS = {"<=": "at most", ">=": "at least", "<": "below", ">": "above"}
_EXPECTED = re.compile(r"[Ee]xpected `(\w+)`(?: (<=|>=|<|>) (\S+))?(?:, got `(\w+)`)?")


def _plain(what: str) -> str:
    """msgspec's "Expected `float` <= 10000.0, got `str`" as "expected a number at most 10000, not text"."""
    def words(match: re.Match[str]) -> str:
        wanted, bound, limit, got = match.groups()
        text = "expected " + _TYPE_WORDS.get(wanted, wanted)
        if bound:
            text += f" {_BOUND_WORDS[bound]} {float(limit):g}"
        if got:
            text += f", not {_TYPE_WORDS.get(got, got)}"
        return text

    return _EXPECTED.sub(words, what)


def describe_problem(error: msgspec.ValidationError, schema: type[AnySettings]) -> str:
    """msgspec's message, in the file's terms and in words: which key, what it takes, and the valid key it most
    likely meant."""
    return _plain(_describe(error, schema))


def _describe(error: msgspec.ValidationError, schema: type[AnySettings]) -> str:
    message = str(error)
    unknown = re.match(r"Object contains unknown field `([^`]*)`", message)
    if unknown:
        key = unknown.group(1)
        return f"unknown key {excerpt(key, 40)}{closest(key, schema.__struct_fields__)}"
    where = re.search(r" - at `\$\.?([^`]*)`", message)
    what = message.split(" - at ")[0]
    if not (where and where.group(1)):
        return what[0].lower() + what[1:]
    key = where.group(1)
    choices = get_args(get_type_hints(schema).get(key))
    if "matching regex" in what:  # a pattern means nothing to a user: say what the value should look like
        return f"{key!r}: {re.sub(r'matching regex .*', 'of the right form', what[0].lower() + what[1:])}" + \
            _example(schema, key.partition("[")[0])
    bad = re.match(r"Invalid enum value (.*)", what)
    if bad and choices:
        word = bad.group(1).strip("'")
        return (f"{key!r}: expected one of {', '.join(map(repr, choices))}, not {excerpt(word, 40)}"
                f"{closest(word, choices)}")
    return f"{key!r}: {what[0].lower()}{what[1:]}"


def validate_settings(kind: DeviceKind, values: dict[str, Any], *, what: str = "option") -> AnySettings:
    """`values` checked against the kind's schema; an unknown or ill-typed value is an InputError naming it."""
    schema = SCHEMAS[kind.name]
    try:
        return msgspec.convert({**values, "kind": kind.name}, type=schema)
    except msgspec.ValidationError as exc:
        problem = describe_problem(exc, schema).replace("unknown key", f"unknown {what}")
        raise refuse("set-value", title=kind.title, problem=problem) from None


def _entry(path: Path, text: str, name: str, table: object, line: int) -> NamedDevice:
    """Device `name` of the file (its section header on `line`, 0 when it has none); a problem is a ConfigError
    naming the line of the key at fault."""

    def fail(problem: str, key: str | None = None) -> ConfigError:
        at = _key_line(text, name, key, line)
        return ConfigError(f"{path}, line {at}: device {excerpt(name, 64)}: {problem}" if at else
                           f"{path}: device {excerpt(name, 64)}: {problem}")

    if not isinstance(table, dict):
        raise fail("must be a table like [devices.NAME]")
    kind_name = table.get("kind")
    if not isinstance(kind_name, str) or kind_name not in KINDS:
        hint = closest(kind_name, KINDS) if isinstance(kind_name, str) else ""
        got = excerpt(kind_name, 20) if isinstance(kind_name, str) else excerpt(repr(kind_name), 20)[1:-1]
        raise fail(f"'kind' must be one of {', '.join(KINDS)} (got {got}){hint}", "kind")
    schema = SCHEMAS[kind_name]
    try:
        settings = msgspec.convert(table, type=schema)
    except msgspec.ValidationError as exc:
        raise fail(describe_problem(exc, schema), _problem_key(exc)) from None
    if not settings.url:
        raise fail("'url' must be a non-empty string such as \"192.168.1.50\" or \"/dev/ttyACM0\"", "url")
    kind = KINDS[kind_name]
    try:
        endpoint = parse_url(settings.url, kind)
    except InputError as exc:
        raise fail(str(exc), "url") from None
    return NamedDevice(name, kind, endpoint, settings, line)


def parse_devices(text: str, path: Path) -> dict[str, NamedDevice]:
    """The devices in a config file's text; any malformed or hostile content is a ConfigError."""
    import tomllib

    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    except (RecursionError, ValueError, MemoryError) as exc:
        # Deep nesting overflows the parser's recursion; a huge integer exceeds Python's digit limit.
        reason = "nested too deeply" if isinstance(exc, RecursionError) else str(exc) or type(exc).__name__
        raise ConfigError(f"{path}: not a usable config file: {reason}") from None
    unknown = set(data) - {"devices"}
    if unknown:
        key = sorted(unknown)[0]
        raise ConfigError(f"{path}: unknown top-level key {excerpt(key, 40)}{closest(key, ['devices'])}; "
                          "expected [devices.NAME] sections")
    devices = data.get("devices", {})
    if not isinstance(devices, dict):
        raise ConfigError(f"{path}: 'devices' must be a table of [devices.NAME] sections")
    if len(devices) > MAX_DEVICES:
        raise ConfigError(f"{path}: {len(devices)} devices is more than the {MAX_DEVICES} a config file may hold")
    lines = section_lines(text)
    found = {name: _entry(path, text, name, table, lines.get(name, 0)) for name, table in devices.items()}
    defaults: dict[str, str] = {}
    for device in found.values():
        if device.default:
            other = defaults.setdefault(device.kind.name, device.name)
            if other != device.name:
                raise ConfigError(f"{path}: devices {excerpt(other, 64)} and {excerpt(device.name, 64)} are both "
                                  f"the default {device.kind.title}: keep `default = true` on one")
    return found


def load_devices(path: Path | None = None) -> dict[str, NamedDevice]:
    """Read the config file; a missing file means no named devices, a malformed one is a ConfigError."""
    path = path or config_path()
    text = read_config_text(path)
    return parse_devices(text, path) if text else {}


def read_config_text(path: Path) -> str:
    """The config file's text ("" for a missing file), read with a bound; unreadable text is a ConfigError."""
    try:
        raw = read_bounded(path, MAX_CONFIG_BYTES)
        if raw is None:
            raise ConfigError(f"{path}: over {MAX_CONFIG_BYTES >> 20} MiB, too large for a config file")
        return raw.decode("utf-8")
    except FileNotFoundError:
        return ""
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # ValueError: a NUL in $FABWIRE_CONFIG
        raise ConfigError(f"cannot read config file {path}: {exc}") from exc


class Target(msgspec.Struct, frozen=True):
    """Where a command goes: the address, and the settings a named device carries."""

    endpoint: Endpoint
    name: str = ""
    options: dict[str, Any] = msgspec.field(default_factory=dict)


def _looks_like_address(text: str) -> bool:
    return "/" in text or ":" in text


_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
"""A device name: POSIX's portable filename characters, not starting with '.', '_' or '-' (`checks.RULES`)."""


def reads_as_address(name: str) -> bool:
    """True for a name `-d` would otherwise take as an address: an IP address, host:port, a URL or a path."""
    if _looks_like_address(name) or WINDOWS_PORT.match(name) or NUMERIC_HOST.fullmatch(name):
        return True
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def check_device_name(name: str) -> str:
    """`name` if every door may take it as a device name (`fabwire.checks.RULES`, door "name"): 1 to 64 of
    letters, digits, '.', '_' and '-', starting with a letter or digit, and not an address's form; an InputError
    worded by the rule it breaks otherwise."""
    if not 0 < len(name) <= MAX_NAME:
        raise refuse("name-length", length=len(name))
    if reads_as_address(name):
        raise refuse("name-address", name=excerpt(name, 64))
    if not _NAME.fullmatch(name):
        raise refuse("name-characters", name=excerpt(name, 64))
    if reads_as_host(name):
        raise refuse("name-host", name=excerpt(name, 64))
    return name


LOCAL_DOMAINS = ("local", "lan", "home", "home.arpa", "internal", "localdomain")
"""The domains of a local network's host names (`checks.RULES["name-host"]`): a name ending in one is a host."""
_HOST_NAME = re.compile(r"localhost|.+\.(?:" + "|".join(re.escape(d) for d in LOCAL_DOMAINS) + r")", re.IGNORECASE)


def reads_as_host(name: str) -> bool:
    """True for a name that is a local network's host name a user would give -d: localhost, pr.local, x.lan."""
    return _HOST_NAME.fullmatch(name.rstrip(".")) is not None  # `localhost.` is the same host, fully qualified


def resolve_target(device: str | None, kind: DeviceKind, path: Path | None = None) -> Target:
    """A -d value may name a configured device or be an address; no -d picks the kind's default device.

    Raises ConfigError for a bad file when the device is (or resembles) a name in it or no device is given, for an
    unknown name that resembles a configured one, a name of another kind, or no device at all; InputError for a
    malformed address. A bad file given an address is a ConfigWarning, and the address is used.
    """
    if device is not None and _looks_like_address(device):
        return Target(parse_url(device, kind))
    path = path or config_path()
    try:
        devices = load_devices(path)
    except ConfigError as problem:
        if device is None or _names_a_section(device, path):
            raise
        # one location for every caller, so a command that resolves twice warns once
        warnings.warn(ConfigWarning(f"{problem}; the file is skipped and {excerpt(device, 64)} taken as an address"),
                      stacklevel=1)
        return Target(parse_url(device, kind))
    if device is None:
        mine = [d for d in devices.values() if d.kind is kind]
        chosen = [d for d in mine if d.default] or (mine if len(mine) == 1 else [])
        if len(chosen) != 1:
            raise ConfigError(
                f"no {kind.title} given: pass -d ADDRESS (or a name from {path}), e.g. -d sim://{kind.name}"
            )
        found = chosen[0]
    elif device in devices:
        found = devices[device]
        if found.kind is not kind:
            raise ConfigError(f"device {excerpt(device, 64)} is {found.kind.a_title}, not {kind.a_title}")
    else:
        hint = _hint(device, devices)
        if hint:
            raise ConfigError(f"no device named {excerpt(device, 64)}{hint}")
        return Target(parse_url(device, kind))
    return Target(found.endpoint, found.name, found.options)


def _hint(device: str, names: object) -> str:
    """` (did you mean 'x'?)` when `device` resembles a configured name; a dotted host name is never a name."""
    return "" if "." in device else closest(device, names)


def _names_a_section(device: str, path: Path) -> bool:
    """Whether `device` may mean a device of a config file that did not load: it names or resembles one of its
    `[devices.NAME]` sections, or the file cannot be read and `device` is a plain word rather than a dotted host
    name or IP address."""
    try:
        names = section_lines(read_config_text(path))
    except ConfigError:
        return "." not in device
    return device in names or bool(_hint(device, names))
