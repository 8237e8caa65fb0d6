"""Every row of the address, name and setting checks (`fabwire.checks.RULES`), through every door that takes one:
`fabwire devices add`, `-d` of the device commands and `fabwire serve --device`. Each refusal is exit 4 and one
short line, the same line whichever door the input came in by, and nothing is written; and whatever `devices add`
saves, `-d NAME` then takes."""

from __future__ import annotations

import contextlib
import io
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.checks import RULES
from fabwire.devices import KINDS
from fabwire.errors import InputError

LONG = "a" * 5000
WIDE = "\U0001f600" * 3000

ADDRESS_CASES: dict[str, list[tuple[str, str]]] = {
    "empty": [("xyz", "   ")],
    "path-too-long": [("xyz", "/dev/" + "x" * 5000), ("mmu", "serial:///" + "y" * 4100)],
    "control": [("xyz", "/dev/tty\x01USB0"), ("lineus", "sim://lineus?name=a%0Ab"), ("xyz", "host\x7f:9100")],
    "invisible": [("xyz", "127.0.0.1\u00a0"), ("lineus", "\u2028line-us.local"), ("xyz", "tcp://pr\u200b.local:9100"),
                  ("mmu", "\ufeff/dev/ttyACM0"), ("xyz", "printer\u3000"), ("xyz", "sim://xyz?model=mini\u00a0w")],
    "scheme": [("xyz", "ftp://printer"), ("xyz", LONG + "://h")],
    "tcp-path": [("xyz", "tcp://printer/x"), ("lineus", "tcp://h:1?x=1")],
    "no-host": [("xyz", "tcp://"), ("lineus", ":1337")],
    "host": [("xyz", "bad host!"), ("xyz", "tcp://" + "h" * 300), ("lineus", "tcp://-x:1337"), ("xyz", WIDE)],
    "ipv4-form": [("xyz", "192.168.1"), ("xyz", "2130706433"), ("lineus", "0x7f000001:1337"), ("xyz", "0177.0.0.1"),
                  ("xyz", "192.168.1.256"), ("mmu", "tcp://10.1:5000"), ("xyz", "127.1.")],
    "bracket": [("lineus", "[::1"), ("lineus", "tcp://[::1:1337")],
    "after-bracket": [("lineus", "[::1]x")],
    "empty-port": [("xyz", "printer:")],
    "port-digits": [("xyz", "printer:abc"), ("xyz", "127.0.0.1:" + "9" * 5000), ("xyz", "h:\u0663")],
    "port-range": [("lineus", "127.0.0.1:99999"), ("xyz", "printer:0")],
    "no-port": [("mmu", "mmu-box"), ("mmu", "tcp://192.0.2.1")],
    "serial-path": [("xyz", "serial://dev/ttyACM0")],
    "sim-path": [("mmu", "sim://mmu/path")],
    "sim-query": [("xyz", "sim://xyz?speed")],
    "fragment": [("xyz", "sim://xyz?speed=5#x"), ("mmu", "sim://mmu#")],
    "sim-unknown": [("xyz", "sim://nosuch"), ("xyz", "sim://" + "x" * 300), ("xyz", "sim://xyz:1")],
    "sim-kind": [("lineus", "sim://xyz"), ("xyz", "sim://lineus"), ("lineus", "sim://mmu?speed=5"),
                 ("mmu", "sim://xyz")],
    "sim-option": [("xyz", "sim://xyz?bogus=1"), ("mmu", "sim://mmu?speeed=5"), ("lineus", "sim://lineus?a=1&b=2"),
                   ("xyz", f"sim://xyz?{LONG}=1"), ("xyz", "sim://xyz?" + "x" * 300 + "=1")],
    "sim-repeated": [("xyz", "sim://xyz?speed=1&speed=2"), ("mmu", "sim://mmu?fault=finda-stuck&fault=finda-stuck")],
    "sim-value": [
        ("xyz", f"sim://xyz?model={LONG}"), ("xyz", "sim://xyz?speed=nan"), ("xyz", "sim://xyz?speed=" + "x" * 300),
        ("xyz", "sim://xyz?fault=nosuch"), ("xyz", "sim://xyz?model=miniMakr"), ("xyz", "sim://xyz?model=dvF100B000"),
        ("xyz", "sim://xyz?link=usb"), ("xyz", "sim://xyz?strict=maybe"), ("xyz", "sim://xyz?serial=" + "S" * 40),
        ("xyz", "sim://xyz?state="), ("mmu", "sim://mmu?version=9.9.9"), ("mmu", f"sim://mmu?version={LONG}"),
        ("mmu", "sim://mmu?fault=finda-stuck@" + "9" * 5000), ("mmu", "sim://mmu?arithmetic=x87"),
        ("mmu", "sim://mmu?speed=inf"), ("lineus", "sim://lineus?version=zz"),
        ("lineus", f"sim://lineus?version={LONG}"), ("lineus", f"sim://lineus?name={LONG}"),
        ("lineus", "sim://lineus?serial=a%20b"), ("lineus", "sim://lineus?reply=later"),
        ("lineus", "sim://lineus?step_time=-1"), ("lineus", "sim://lineus?speed=-5"),
    ],
}
NAME_CASES: dict[str, list[str]] = {
    "name-length": ["n" * 65, "x" * 5000],
    "name-address": ["127.0.0.1", "::1", "10.0.0.5:9100", "tcp://office", "/dev/ttyUSB0", "fe80::1", "COM3", "127.1",
                     "2130706433", "0x7f000001", "0177.0.0.1", "10.0.0.5."],
    "name-host": ["localhost", "LOCALHOST", "pr.local", "line-us.LOCAL", "printer.lan", "jr.home", "jr.home.arpa",
                  "mini.internal", "box.localdomain", "localhost.", "printer.local.", "a.local.."],
    "name-characters": ["my printer", "tab\there", "bench\u00e9", "_hidden", ".dot", "semi;colon", "a$b", "q'uote",
                        "\U0001f600", "star*"],
}
SETTING_CASES: dict[str, list[tuple[str, str]]] = {
    "set-form": [("xyz", "model"), ("xyz", "=5"), ("xyz", LONG)],
    "set-reserved": [("xyz", "default=true"), ("xyz", "url=127.0.0.1"), ("lineus", "kind=xyz")],
    "set-unknown": [("xyz", "defualt=true"), ("xyz", f"{LONG}=1"), ("mmu", "sped=5"), ("lineus", "look_ahead=true")],
    "set-control": [("xyz", "model=mini\nw"), ("mmu", "speed=a\x1bb")],
    "set-value": [("xyz", f"link={LONG}"), ("xyz", "reply_timeout=-5"), ("mmu", "accept=3.0"),
                  ("lineus", "lookahead=maybe"), ("mmu", "speed=1e400"), ("mmu", "speed=1e-300"),
                  ("mmu", "speed=0.001")],
    "set-model": [("xyz", "model=miniMakr"), ("xyz", f"model={LONG}")],
}
FILE_CASES: dict[str, list[tuple[str, str]]] = {
    "file-empty": [("", ""), ("  ", "/")],
    "file-part": [("..", ""), ("a.gcode", "../up"), ("C:\\part.gcode", ""), ("a|b.gcode", ""), ("ok.gcode", "x:y"),
                  ("ok.gcode", "trailing /"), ("part.gcode\u00a0", "")],
    "file-hidden": [("\u202e" + "edocg.exe", ""), ("part\u200b.gcode", ""), ("\ufeffpart.gcode", ""),
                    ("part.gcode", "\u2066folder\u2069"), ("soft\u00adhyphen.gcode", ""), ("line\u2028break.gcode", ""),
                    ("c1\x85.gcode", ""), ("mark\u200f.gcode", ""), ("arabic\u061c.gcode", ""),
                    ("undecoded\udcff.gcode", ""), ("esc\x1b[2J.gcode", ""), ("nul\x00.gcode", ""),
                    ("tag\U000e0001.gcode", ""), ("filler\u115f.gcode", ""), ("ok.gcode", "x\x00y")],
    "file-length": [("x" * 201, ""), ("b.gcode", "f" * 195)],
}
"""Upload names (file, folder) each `file-*` rule refuses."""
PLAIN_NAMES = [("\u0645\u06cc\u200c\u062e\u0648\u0627\u0647\u0645.gcode", ""), ("\U0001f468\u200d\U0001f373.gcode", ""),
               ("\u6a21\u578b\u3000\uff11.gcode", ""), ("caf\u00e9.gcode", "projects/2026"),
               ("heart\u2764\ufe0f.gcode", "")]
"""Names kept as they are: Persian and emoji spell with the zero-width (non-)joiner and variation selectors, CJK
names hold ideographic spaces."""
ADDRESS_ROWS = [(code, kind, address) for code, cases in ADDRESS_CASES.items() for kind, address in cases]
MAX_LINE = 300
"""A refusal's line, however long the input: short enough to read on one terminal line or two."""


def test_every_rule_has_cases() -> None:
    assert set(ADDRESS_CASES) | set(NAME_CASES) | set(SETTING_CASES) | set(FILE_CASES) == set(RULES)
    for code, rule in RULES.items():
        cases = {"address": ADDRESS_CASES, "simulator": ADDRESS_CASES, "name": NAME_CASES, "setting": SETTING_CASES,
                 "file": FILE_CASES}
        assert code in cases[rule.door], code
        assert rule.source
        assert rule.refused
        assert rule.why


def fixed_words(code: str) -> str:
    """The longest run of a rule's reason that no field fills in: every refusal by that rule says it."""
    template = RULES[code].why
    pieces = [piece.split("}", 1)[-1] for piece in template.split("{")]
    return max(pieces, key=len).strip()


def refusal(result: object, code: str, what: str) -> str:
    """The one line a door refused with, checked: exit 4, one short line on stderr, the rule's words."""
    assert result.returncode == InputError.exit_code, (what, result.stderr)  # type: ignore[attr-defined]
    stderr: str = result.stderr  # type: ignore[attr-defined]
    assert "Traceback" not in stderr, what
    assert stderr.count("\n") == 1, (what, stderr)
    assert stderr.startswith("fabwire: error: "), (what, stderr)
    assert len(stderr) < MAX_LINE, (what, stderr)
    assert fixed_words(code) in stderr, (code, what, stderr)
    return stderr


COMMAND = {"xyz": ["xyz", "-d", "{}", "status"], "lineus": ["lineus", "-d", "{}", "info"],
           "mmu": ["mmu", "-d", "{}", "version"]}


def doors(kind: str, address: str, tmp_path: Path, name: str = "bench") -> dict[str, list[str]]:
    state = str(tmp_path / "state")
    return {
        "devices add": ["devices", "add", name, address, "--kind", kind],
        "-d": [part.replace("{}", address) for part in COMMAND[kind]],
        "serve --device": ["serve", "--listen", "127.0.0.1:0", "--state-dir", state,
                           "--device", f"{name}:{kind}={address}"],
    }


def env_in(tmp_path: Path) -> dict[str, str]:
    env = cli_env()
    env["FABWIRE_CONFIG"] = str(tmp_path / "devices.toml")
    return env


def refused_alike(code: str, commands: dict[str, list[str]], tmp_path: Path) -> None:
    """Each door refuses by rule `code` with the same one line, and writes nothing: no config file, no state."""
    lines = {door: refusal(run_cli(*args, env=env_in(tmp_path)), code, door) for door, args in commands.items()}
    assert len(set(lines.values())) == 1, lines
    assert not (tmp_path / "devices.toml").exists()
    assert not (tmp_path / "state").exists()  # serve refused before it started anything


def short(value: object) -> object:
    return value[:30] if isinstance(value, str) else value


@pytest.mark.parametrize(("code", "kind", "address"), ADDRESS_ROWS, ids=short)
def test_an_address_is_refused_alike_by_every_door(code: str, kind: str, address: str, tmp_path: Path) -> None:
    refused_alike(code, doors(kind, address, tmp_path), tmp_path)


@pytest.mark.parametrize(("code", "name"), [(code, name) for code, names in NAME_CASES.items() for name in names],
                         ids=short)
def test_a_name_is_refused_alike_by_every_door(code: str, name: str, tmp_path: Path) -> None:
    chosen = doors("xyz", "127.0.0.1", tmp_path, name)
    refused_alike(code, {door: chosen[door] for door in ("devices add", "serve --device")}, tmp_path)


@pytest.mark.parametrize(("code", "kind", "setting"),
                         [(code, kind, setting) for code, cases in SETTING_CASES.items() for kind, setting in cases],
                         ids=short)
def test_a_setting_is_refused_in_one_short_line(code: str, kind: str, setting: str, tmp_path: Path) -> None:
    refused_alike(code, {"devices add": ["devices", "add", "bench", "/dev/ttyACM0", "--kind", kind, "--set", setting]},
                  tmp_path)


@pytest.mark.parametrize(("code", "kind", "address"), ADDRESS_ROWS, ids=short)
def test_the_config_file_and_the_api_refuse_an_address_in_the_same_words(code: str, kind: str, address: str,
                                                                         tmp_path: Path) -> None:
    """The two doors that are not command lines: a devices.toml written by hand (its line named) and the agent
    API's device list (a 400 with the message)."""
    import json

    from fabwire.agent.api import NewDevice, checked_address
    from fabwire.config import parse_devices
    from fabwire.errors import ConfigError
    from fabwire.transport.urls import parse_url

    with pytest.raises(InputError) as expected:
        parse_url(address, KINDS[kind])
    words = str(expected.value)
    assert fixed_words(code) in words
    path = tmp_path / "devices.toml"
    written = json.dumps(address, ensure_ascii=False).replace("\x7f", "\\u007f")  # TOML's escapes of JSON's
    with pytest.raises(ConfigError) as in_file:
        parse_devices(f'[devices.bench]\nkind = "{kind}"\nurl = {written}\n', path)
    assert str(in_file.value) == f"{path}, line 3: device 'bench': {words}"
    if len(address) <= 300:  # the API's bound on an address's length (a 422 before any check)
        with pytest.raises(InputError) as over_api:
            checked_address(NewDevice(name="bench", kind=kind, address=address))
        assert str(over_api.value) == words


def test_a_misspelt_setting_suggests_only_what_set_takes(tmp_path: Path) -> None:
    env = env_in(tmp_path)
    said = run_cli("devices", "add", "a1", "127.0.0.1", "--kind", "xyz", "--set", "defualt=true", env=env).stderr
    assert "did you mean 'default'" not in said
    assert "give default with --default" in said
    said = run_cli("devices", "add", "a1", "127.0.0.1", "--kind", "xyz", "--set", "model=miniMakr", env=env).stderr
    assert said == "fabwire: error: unknown printer model 'miniMakr' (did you mean 'miniMaker'?)\n"


def test_a_device_of_another_kind_is_named_with_its_article(tmp_path: Path) -> None:
    env = env_in(tmp_path)
    assert run_cli("devices", "add", "desk", "sim://xyz", "--kind", "xyz", env=env).returncode == 0
    assert run_cli("devices", "add", "arm", "sim://lineus", "--kind", "lineus", env=env).returncode == 0
    assert run_cli("devices", "add", "box", "sim://mmu", "--kind", "mmu", env=env).returncode == 0
    said = {
        ("lineus", "desk"): "device 'desk' is an XYZprinting da Vinci, not a Line-us",
        ("mmu", "desk"): "device 'desk' is an XYZprinting da Vinci, not a Prusa MMU3",
        ("xyz", "arm"): "device 'arm' is a Line-us, not an XYZprinting da Vinci",
        ("xyz", "box"): "device 'box' is a Prusa MMU3, not an XYZprinting da Vinci",
    }
    for (kind, name), words in said.items():
        done = run_cli(*[part.replace("{}", name) for part in COMMAND[kind]], env=env)
        assert done.returncode == 3, done.stderr
        assert done.stderr == f"fabwire: error: {words}\n"


# --------------------------------------------------------------------- what devices add saves, -d takes

OPTION_NAMES = ["model", "speed", "link", "fault", "strict", "state", "store", "serial", "control", "version",
                "name", "reply", "step_time", "arithmetic", "phantom_requests", "speeed", "bogus"]
VALUES = st.one_of(
    st.sampled_from(["1", "0", "50", "nan", "inf", "-1", "1e400", "wifi", "serial", "nano", "miniMaker", "3.0.3",
                     "9.9.9", "3", "1.0.1", "zz", "bot", "door-open", "finda-stuck", "finda-stuck:2", "accept",
                     "complete", "pc", "avr", "yes", "ABC123", "x/y", "", "a%20b", "x%26y", "dvF100B000"]),
    st.text(max_size=12),
)
SIM_ADDRESSES = st.builds(
    lambda name, pairs: f"sim://{name}" + ("?" + "&".join(f"{k}={v}" for k, v in pairs) if pairs else ""),
    st.sampled_from(["xyz", "lineus", "mmu", "", "nosuch"]),
    st.lists(st.tuples(st.sampled_from(OPTION_NAMES), VALUES), max_size=3),
)
ADDRESSES = st.one_of(
    SIM_ADDRESSES,
    st.builds(lambda host, port: f"{host}{port}", st.sampled_from(["127.0.0.1", "printer", "[::1]", "tcp://h", "",
                                                                    "bad host", "tcp://"]),
              st.sampled_from(["", ":1", ":65535", ":0", ":99999", ":x", ":"])),
    st.sampled_from(["/dev/ttyACM0", "serial:///dev/ttyUSB0", "COM3", "serial://x"]),
    st.text(max_size=20),
)
NAMES = st.one_of(st.from_regex(r"[A-Za-z0-9][A-Za-z0-9._-]{0,10}", fullmatch=True), st.text(max_size=12))


def _build_simulator(endpoint: object) -> None:
    """Start-up of the simulator the address names, as `-d` would do it (without serving)."""
    from fabwire.lineus.sim import options_from
    from fabwire.mmu.sim import options_to_simulator
    from fabwire.xyz.sim import simulator_from_options

    build = {"xyz": simulator_from_options, "lineus": options_from, "mmu": options_to_simulator}
    build[endpoint.host](endpoint.options)  # type: ignore[attr-defined]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(name=NAMES, kind=st.sampled_from(["xyz", "lineus", "mmu"]), address=ADDRESSES)
@example(name="q1", kind="xyz", address="sim://xyz?speed=nan")
@example(name="l2", kind="lineus", address="sim://xyz")
@example(name="m1", kind="mmu", address="sim://mmu?version=9.9.9&speed=50")
@example(name="x", kind="xyz", address="sim://xyz?fault=door-open+stuck&model=nano")
@example(name="s", kind="xyz", address="sim://xyz?state=/tmp/a%26b")
@example(name="t", kind="lineus", address="sim://lineus?speed=0&name=bot&serial=42&reply=accept")
def test_what_devices_add_saves_dash_d_takes(name: str, kind: str, address: str) -> None:
    from fabwire.agent.command import checked_device
    from fabwire.agent.core import DeviceSpec
    from fabwire.cli import main
    from fabwire.devices import KINDS
    from fabwire.opening import plan_link

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "devices.toml"
        errors = io.StringIO()
        with (contextlib.redirect_stderr(errors), contextlib.redirect_stdout(io.StringIO()),
              pytest.MonkeyPatch.context() as patch):
            patch.setenv("FABWIRE_CONFIG", str(path))
            code = main(["devices", "add", "--kind", kind, "--", name, address])
        try:
            checked_device(DeviceSpec(name, kind, address))  # type: ignore[arg-type]
            served = True
        except InputError:
            served = False
        event("saved" if code == 0 else "refused")
        assert served == (code == 0), (errors.getvalue(), served)  # serve --device agrees with devices add
        if code != 0:
            assert code == InputError.exit_code, errors.getvalue()
            assert errors.getvalue().count("\n") == 1, errors.getvalue()
            assert len(errors.getvalue()) < MAX_LINE, errors.getvalue()
            assert not path.exists()
            return
        link = plan_link(KINDS[kind], name, {"config": str(path)})  # -d NAME: the file, the name, the address
        assert link.endpoint is not None
        if link.endpoint.scheme == "sim":
            with contextlib.chdir(folder):  # a relative state or store path lands in the throwaway folder
                _build_simulator(link.endpoint)
        else:
            assert link.endpoint.scheme != "tcp" or 1 <= link.endpoint.port <= 65535


def test_a_saved_simulator_answers_through_dash_d(tmp_path: Path) -> None:
    env = env_in(tmp_path)
    for name, kind, address in (("p", "xyz", "sim://xyz?speed=50&fault=door-open+stuck&model=nano&serial=AB12"),
                                ("a", "lineus", "sim://lineus?speed=0&name=bot&serial=42&reply=accept"),
                                ("m", "mmu", "sim://mmu?speed=50&version=3.0.3&arithmetic=avr")):
        added = run_cli("devices", "add", name, address, "--kind", kind, env=env)
        assert added.returncode == 0, added.stderr
        done = run_cli(*[part.replace("{}", name) for part in COMMAND[kind]], env=env)
        assert done.returncode == 0, done.stderr


@settings(max_examples=200, deadline=None)
@given(kind=st.sampled_from(["xyz", "lineus", "mmu"]), serial=st.none() | st.text(max_size=600),
       address=st.text(max_size=5000) | st.builds(lambda n: f"sim://xyz?state=/{'a' * n}", st.integers(0, 4000)))
@example(kind="xyz", serial=None, address="sim://xyz?model=" + LONG)
@example(kind="xyz", serial="S" * 500, address="127.0.0.1")
def test_a_device_id_fits_a_file_name_and_a_topic_level(kind: str, serial: str | None, address: str) -> None:
    """The agent names a device's folders and MQTT topics by its id: at most MAX_DEVICE_ID of a-z, 0-9 and '-'
    (within NAME_MAX, and no MQTT wildcard or level separator), and two long addresses keep two ids."""
    import re

    from fabwire.agent.core import MAX_DEVICE_ID, device_id

    made = device_id(kind, serial, address, host="bench-pc")
    assert len(made) <= MAX_DEVICE_ID
    assert re.fullmatch(r"[a-z0-9-]+", made)
    if len(made) == MAX_DEVICE_ID:  # cut: the hash of the whole keeps a longer neighbour apart
        other = device_id(kind, serial + "x", address, host="bench-pc") if serial and serial.strip() else \
            device_id(kind, serial, address + "x", host="bench-pc")
        assert other != made


@pytest.mark.parametrize("name", ["jr-2.0", "mini.1", "lab.mini", "localhost2", "my.local.jr", "v1.2.3", "home"])
def test_a_name_outside_a_local_network_domain_is_a_name(name: str, tmp_path: Path) -> None:
    env = env_in(tmp_path)
    added = run_cli("devices", "add", name, "127.0.0.1", "--kind", "xyz", env=env)
    assert added.returncode == 0, added.stderr
    assert name in run_cli("devices", "list", env=env).stdout


@pytest.mark.parametrize(("code", "name", "folder"),
                         [(code, name, folder) for code, cases in FILE_CASES.items() for name, folder in cases])
def test_an_upload_name_is_refused_by_its_rule(code: str, name: str, folder: str) -> None:
    """The one check every upload door's names pass through (`clean_name`; the agent's doors in
    tests/agent/test_upload_names.py)."""
    from fabwire.agent.library import clean_name

    with pytest.raises(InputError) as refused:
        clean_name(name, folder)
    assert fixed_words(code) in str(refused.value)
    assert len(str(refused.value)) < MAX_LINE


@pytest.mark.parametrize(("name", "folder"), PLAIN_NAMES)
def test_names_in_any_script_are_kept_as_written(name: str, folder: str) -> None:
    from fabwire.agent.library import clean_name

    assert clean_name(name, folder) == f"{folder}/{name}".lstrip("/")
