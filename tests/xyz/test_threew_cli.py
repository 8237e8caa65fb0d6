from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import cli_env, run_cli
from fabwire.cli_support import App
from fabwire.errors import InputError
from fabwire.xyz.intake import gcode_metadata as intake_metadata
from fabwire.xyz.threew import read_3w
from fabwire.xyz.threew_cli import convert, info

DATA = Path(__file__).parent / "data" / "threew"
TV_INPUT = (DATA / "tv_input.gcode").read_bytes()


def invoke(command, *args: str, json_mode: bool = False, input: bytes | None = None):  # type: ignore[no-untyped-def]
    app = App()
    app.output.json_mode = json_mode
    return CliRunner().invoke(command, list(args), obj=app, input=input)


@pytest.fixture
def gcode(tmp_path: Path) -> Path:
    path = tmp_path / "part.gcode"
    path.write_bytes(TV_INPUT)
    return path


def test_convert_gcode_to_3w_and_back(gcode: Path, tmp_path: Path) -> None:
    result = invoke(convert, str(gcode), str(tmp_path / "part.3w"), "--model", "mini w")
    assert result.exit_code == 0, result.output
    assert "wrote" in result.output
    assert "da Vinci mini w" in result.output
    decoded = read_3w(tmp_path / "part.3w")
    assert decoded.machine == "dv1MW0A000"
    assert decoded.fields["filename"] == "part.3w"
    result = invoke(convert, str(tmp_path / "part.3w"), str(tmp_path / "back.gcode"), json_mode=True)
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["direction"] == "3w-to-gcode"
    assert data["crc_ok"] is True
    assert data["model"]["model_number"] == "dv1MW0A000"
    assert (tmp_path / "back.gcode").read_bytes() == decoded.gcode


def test_convert_defaults_to_minimaker_and_honours_format_and_zip(gcode: Path, tmp_path: Path) -> None:
    assert invoke(convert, str(gcode), str(tmp_path / "a.3w")).exit_code == 0
    assert read_3w(tmp_path / "a.3w").model is not None
    assert read_3w(tmp_path / "a.3w").machine == "dv1MX0A000"
    assert invoke(convert, str(gcode), str(tmp_path / "b.3w"), "-m", "nano", "--format", "v5").exit_code == 0
    nano = read_3w(tmp_path / "b.3w")
    assert (nano.container, nano.header_encrypted, nano.machine) == (5, False, "dv1NX0A000")
    assert invoke(convert, str(gcode), str(tmp_path / "c.3w"), "--zip").exit_code == 0
    assert read_3w(tmp_path / "c.3w").zipped
    assert invoke(convert, str(gcode), str(tmp_path / "d.3w"), "-m", "1.0", "--no-zip").exit_code == 0
    assert read_3w(tmp_path / "d.3w").tag == "TagEJ256"


def test_convert_retargets_a_3w(tmp_path: Path) -> None:
    result = invoke(convert, str(DATA / "tv1_minimaker_v2.3w"), str(tmp_path / "pro.3w"), "-m", "dv1JP0A000",
                    json_mode=True)
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["direction"] == "3w-to-3w"
    pro = read_3w(tmp_path / "pro.3w")
    assert (pro.container, pro.machine, pro.print_time_s) == (5, "dv1JP0A000", 600)
    assert pro.gcode.endswith(
        b";TIME:600\n;LAYER_COUNT:3\n;Filament used: 0.25m\nG28\nG1 X10 Y10\nG1 X20 Y20 E1\nM84\n")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["{gcode}", "{tmp}/out.gcode"], "nothing to convert"),
        (["{tv1}", "{tmp}/out.gcode", "--model", "nano"], "only apply when writing"),
        (["{gcode}", "{tmp}/out.3w", "--model", "prusa"], "unknown printer model"),
        (["{tmp}/missing.gcode", "{tmp}/out.3w"], "cannot read"),
    ],
)
def test_convert_refuses_bad_requests(args: list[str], message: str, gcode: Path, tmp_path: Path) -> None:
    filled = [a.format(gcode=gcode, tmp=tmp_path, tv1=DATA / "tv1_minimaker_v2.3w") for a in args]
    result = invoke(convert, *filled)
    assert isinstance(result.exception, InputError)
    assert message in str(result.exception)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["part.gcode"]


def test_info_human_and_json() -> None:
    result = invoke(info, str(DATA / "tv2_jr_pro_v5.3w"))
    assert result.exit_code == 0, result.output
    for text in ("v5 TagEJ256", "plaintext", "ok", "da Vinci Jr. 1.0 Pro (dv1JP0A000)", "10m 00s", "250.0 mm"):
        assert text in result.output
    result = invoke(info, str(DATA / "tv1_minimaker_v2.3w"), json_mode=True)
    data = json.loads(result.stdout)
    assert data["variant"] == "v2 TagEJ256"
    assert data["crc_stored"] == "49b4a4a3"
    assert data["crc_ok"] is True
    assert data["header_encrypted"] is True
    assert data["fields"]["machine"] == "dv1MX0A000"
    assert data["layers"] == 3


def test_info_reports_a_crc_mismatch(tmp_path: Path) -> None:
    damaged = bytearray((DATA / "tv1_minimaker_v2.3w").read_bytes())
    damaged[4719] ^= 1
    (tmp_path / "bad.3w").write_bytes(bytes(damaged))
    result = invoke(info, str(tmp_path / "bad.3w"))
    assert result.exit_code == 0
    assert "MISMATCH (computed 49b4a4a3)" in result.output


def test_info_on_gcode_shows_what_a_conversion_would_use(gcode: Path, tmp_path: Path) -> None:
    data = json.loads(invoke(info, str(gcode), json_mode=True).stdout)
    assert (data["slicer"], data["print_time_s"], data["filament_mm"], data["layers"]) == (None, 600, 250.0, 3)
    plain = tmp_path / "plain.gcode"
    plain.write_bytes(b"G28\nG1 Z0.2 F600\nG1 X10 E1\n")
    data = json.loads(invoke(info, str(plain), json_mode=True).stdout)
    assert data["sources"] == {"print_time_s": "computed", "filament_mm": "computed", "layers": "computed"}
    assert data["filament_mm"] == 1.0
    other = tmp_path / "notes.txt"
    other.write_text("hello")
    assert "is text, not G-code" in str(invoke(info, str(other)).exception)


# ------------------------------------------------------------------------------------------ as real subprocesses


def test_cli_subprocess_round_trip(gcode: Path, tmp_path: Path) -> None:
    env = cli_env(tmp_path)
    done = run_cli("--json", "xyz", "convert", str(gcode), str(tmp_path / "p.3w"), "--model", "dv1JP0A000", env=env)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["variant"] == "v5 TagEJ256"
    done = run_cli("xyz", "info", str(tmp_path / "p.3w"), env=env)
    assert done.returncode == 0, done.stderr
    assert "da Vinci Jr. 1.0 Pro" in done.stdout
    done = run_cli("xyz", "convert", str(tmp_path / "p.3w"), str(tmp_path / "p.gcode"), env=env)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "p.gcode").read_bytes() == read_3w(tmp_path / "p.3w").gcode


def test_cli_subprocess_errors_are_one_line_with_input_exit_code(tmp_path: Path) -> None:
    env = cli_env(tmp_path)
    bad = tmp_path / "bad.3w"
    bad.write_bytes((DATA / "tv1_minimaker_v2.3w").read_bytes()[:8200])
    done = run_cli("xyz", "convert", str(bad), str(tmp_path / "out.gcode"), env=env)
    assert done.returncode == InputError.exit_code
    assert done.stderr.strip().count("\n") == 0
    assert "not a multiple of 16" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "out.gcode").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.3w"]
    done = run_cli("xyz", "info", str(bad), env=env)
    assert done.returncode == InputError.exit_code
    assert "not a multiple of 16" in done.stderr


def test_cli_subprocess_large_file_keeps_stdout_clean(tmp_path: Path) -> None:
    line = b"G1 X10.000 Y20.000 E0.01234 F1800\n"
    big = tmp_path / "big.gcode"
    big.write_bytes(b";TIME:5\n;LAYER_COUNT:1\n;Filament used: 1m\nG28\n" + line * (9_000_000 // len(line)))
    done = run_cli("--json", "xyz", "convert", str(big), str(tmp_path / "big.3w"), env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    data = json.loads(done.stdout)
    assert data["written_bytes"] == (tmp_path / "big.3w").stat().st_size
    assert data["gcode_bytes"] > 9_000_000


def _piped(*args: str, data: bytes) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([sys.executable, "-m", "fabwire", *args], input=data, capture_output=True,
                          env=cli_env(), timeout=120)


def test_convert_and_info_read_standard_input_as_they_read_a_file(gcode: Path, tmp_path: Path) -> None:
    (tmp_path / "piped").mkdir()
    piped = _piped("xyz", "convert", "-", str(tmp_path / "piped" / "part.3w"), "-m", "mini w", data=TV_INPUT)
    assert piped.returncode == 0, piped.stderr
    assert invoke(convert, str(gcode), str(tmp_path / "part.3w"), "-m", "mini w").exit_code == 0
    made = (tmp_path / "piped" / "part.3w").read_bytes()
    assert read_3w(made).gcode == read_3w(tmp_path / "part.3w").gcode
    shown = _piped("--json", "xyz", "info", "-", data=made)
    assert shown.returncode == 0, shown.stderr
    assert json.loads(shown.stdout)["machine"] == "dv1MW0A000"
    back = _piped("xyz", "convert", "-", str(tmp_path / "back.gcode"), data=made)
    assert back.returncode == 0, back.stderr
    assert (tmp_path / "back.gcode").read_bytes() == read_3w(made).gcode


@pytest.mark.parametrize(("data", "message"), [
    (b"", "standard input is empty: nothing to print"),
    (b"\x00\x01\x02junk", "standard input is binary data, not G-code or a .3w print file"),
    (bytes(80) + (2).to_bytes(4, "little") + bytes(100), "standard input is an STL model"),  # told by its size
    (b"G28\n;" + b"x" * (2 << 20) + b"\nG1 X1\n", "has a line of over"),  # the streaming line limit holds
])
def test_standard_input_that_cannot_be_converted_is_one_line_of_error(data: bytes, message: str,
                                                                      tmp_path: Path) -> None:
    done = _piped("xyz", "convert", "-", str(tmp_path / "out.3w"), data=data)
    assert done.returncode == 4
    assert message in done.stderr.decode()
    assert len(done.stderr.decode().strip().splitlines()) == 1
    assert not (tmp_path / "out.3w").exists()


ENDLESS = ("import sys\nhead = bytes.fromhex(sys.argv[1])\nout = sys.stdout.buffer\nout.write(head)\n"
           "while True:\n    out.write(bytes(1 << 20))\n")
"""A producer that writes its first bytes, then zeros until its reader goes away."""


@pytest.mark.parametrize(("head", "what"), [
    (b"", "binary data"),
    (b"\x89PNG\r\n\x1a\n", "an image (PNG)"),
    (b"\x1f\x8b\x08\x00", "gzip-compressed"),
    (b"PK\x03\x04", "a zip archive"),
    (b"%PDF-1.7\n", "a PDF document"),
    (b"G28\nG1 X10\n" + b"\x01\xfe" * 100, "binary data"),  # declares no STL size within the limit
])
@pytest.mark.parametrize("command", ["convert", "info"])
def test_standard_input_that_is_no_print_file_is_refused_from_its_first_block(head: bytes, what: str, command: str,
                                                                              tmp_path: Path) -> None:
    producer = subprocess.Popen([sys.executable, "-c", ENDLESS, head.hex()], stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL)
    try:
        args = ["xyz", command, "-", *([str(tmp_path / "out.3w")] if command == "convert" else [])]
        assert producer.stdout is not None
        done = subprocess.run([sys.executable, "-m", "fabwire", *args], stdin=producer.stdout, capture_output=True,
                              env=cli_env(), timeout=300)
    finally:
        producer.kill()
        producer.wait()
    assert done.returncode == 4, done.stderr
    said = done.stderr.decode().strip().splitlines()
    assert len(said) == 1, said
    assert said[0].startswith(f"fabwire: error: standard input is {what}"), said
    assert not (tmp_path / "out.3w").exists()


def test_standard_input_that_never_ends_is_cut_off(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from fabwire.xyz import intake

    monkeypatch.setattr(intake, "MAX_STDIN", 1 << 20)
    result = invoke(convert, "-", str(tmp_path / "out.3w"), input=b"G1 X1\n" * 400_000)
    assert isinstance(result.exception, InputError)
    assert str(result.exception).startswith("standard input is over")
    assert not (tmp_path / "out.3w").exists()


def test_file_names_that_are_not_utf8_convert_both_ways(gcode: Path, tmp_path: Path) -> None:
    src = tmp_path / os.fsdecode(b"part\xff.gcode")
    src.write_bytes(TV_INPUT)
    out = tmp_path / os.fsdecode(b"out\xfe.3w")
    done = run_cli("--json", "xyz", "convert", str(src), str(out), env=cli_env())
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["output"] == str(out)
    assert read_3w(out).fields["filename"] == "out\ufffd.3w"  # the name's bytes kept, shown with a replacement
    back = _piped("xyz", "convert", str(out), str(tmp_path / os.fsdecode(b"back\xfd.gcode")), data=b"")
    assert back.returncode == 0, back.stderr
    assert b"back\xfd.gcode" in back.stdout  # the name as the file system has it


@settings(max_examples=40, deadline=None)
@given(axis=st.sampled_from("XYZE"), digits=st.integers(12, 400), header=st.booleans())
def test_numbers_no_printer_reaches_are_refused_not_converted(tmp_path_factory: pytest.TempPathFactory, axis: str,
                                                              digits: int, header: bool) -> None:
    folder = tmp_path_factory.mktemp("absurd")
    huge = "9" * digits
    text = (f";TIME:{huge}\n" if header else "") + f"G28\nG1 X10 Y10 Z0.2 E1 F1200\nG1 {axis}{huge} F1200\nM84\n"
    path = folder / "absurd.gcode"
    path.write_text(text)
    with pytest.raises(InputError, match="this is not a print file"):
        intake_metadata(path)


def test_an_ordinary_long_print_is_not_called_absurd(tmp_path: Path) -> None:
    path = tmp_path / "long.gcode"
    layers = "".join(f"G1 Z{z / 10:.1f}\nG1 X180 Y180 E{z * 20}\nG1 X0 Y0 E{z * 20 + 10}\n" for z in range(1, 2000))
    path.write_text("G28\nG1 F600\n" + layers)
    _, computed = intake_metadata(path)
    assert computed is not None
    assert computed.print_time_s is not None
    assert computed.print_time_s > 3600  # over an hour of real printing is believed


@settings(max_examples=60, deadline=None)
@given(line=st.sampled_from([";TIME:{n}", ";LAYER_COUNT:{n}", ";Filament used: {n}m",
                             "; estimated printing time (normal mode) = {n}d 2h", "; total layers count = {n}",
                             "; facets = {n}", "; filament used [mm] = {n}"]),
       digits=st.integers(1, 5000))
def test_any_stated_figure_is_believed_or_set_aside_never_a_crash(tmp_path_factory: pytest.TempPathFactory,
                                                                  line: str, digits: int) -> None:
    path = tmp_path_factory.mktemp("stated") / "stated.gcode"
    path.write_text(line.format(n="9" * digits) + "\nG28\nG1 X10 Y10 Z0.2 E1 F1200\n")
    stated, computed = intake_metadata(path)
    assert all(v is None or v <= 10**8 for v in (stated.layers, stated.facets))
    assert stated.print_time_s is None or stated.print_time_s <= 90 * 86400
    if digits >= 19 and "facets" not in line:
        assert stated.notes  # no print has such a figure: said so, and computed
        assert computed is not None


_LOADED = ("import sys\nfrom fabwire.__main__ import run\nsys.argv = ['fabwire', *sys.argv[1:]]\n"
           "try:\n    run()\nexcept SystemExit as exc:\n    code = exc.code\n"
           "print('rich' in sys.modules, file=sys.stderr)\nsys.exit(code)\n")


def _big_gcode(path: Path) -> Path:
    from fabwire.xyz.threew_cli import BAR_THRESHOLD

    line = b"G1 X10.5 Y20.25 E0.125\nG1 X30.5 Y40.25 E0.25\n"
    path.write_bytes(b"M83\nG28\n" + line * (BAR_THRESHOLD // len(line) + 1))
    return path


def test_a_large_conversion_off_a_terminal_draws_no_bar_and_loads_no_rich(tmp_path: Path) -> None:
    src = _big_gcode(tmp_path / "big.gcode")
    done = subprocess.run([sys.executable, "-c", _LOADED, "xyz", "convert", str(src), str(tmp_path / "big.3w")],
                          capture_output=True, timeout=300, env=cli_env(tmp_path))
    assert done.returncode == 0, done.stderr
    assert done.stderr.decode().splitlines() == ["False"]  # nothing drawn, and rich never imported
    assert b"wrote" in done.stdout
    assert read_3w(tmp_path / "big.3w").gcode.endswith(b"G1 X30.5 Y40.25 E0.25\n")


def test_a_large_conversion_on_a_terminal_draws_its_bar(tmp_path: Path) -> None:
    import pty
    import select

    src = _big_gcode(tmp_path / "big.gcode")
    env = cli_env(tmp_path)
    env["TERM"] = "xterm"
    pid, fd = pty.fork()
    if pid == 0:  # the child: the command on the terminal
        os.execve(sys.executable, [sys.executable, "-m", "fabwire", "xyz", "convert", str(src),
                                   str(tmp_path / "big.3w")], env)
    said = b""
    try:
        while select.select([fd], [], [], 120)[0]:  # a bound against hanging, not a pass/fail window
            try:
                chunk = os.read(fd, 65536)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            said += chunk
        _, status = os.waitpid(pid, 0)
    finally:
        os.close(fd)
    assert os.waitstatus_to_exitcode(status) == 0, said[-2000:]
    assert b"encoding big.3w" in said
    assert b"wrote" in said


def test_without_dst_the_output_is_named_after_the_source(tmp_path: Path) -> None:
    """part.gcode → part.3w and part.3w → part.gcode; a file of that name is never replaced unless named (it may
    be the source itself, a G-code named .3w), and standard input needs DST."""
    src = tmp_path / "part.gcode"
    src.write_bytes(TV_INPUT)
    made = run_cli("xyz", "convert", str(src), env=cli_env())
    assert made.returncode == 0, made.stderr
    assert read_3w(tmp_path / "part.3w").gcode  # written beside the source
    (tmp_path / "back").mkdir()
    moved = tmp_path / "back" / "part.3w"
    (tmp_path / "part.3w").rename(moved)
    back = run_cli("xyz", "convert", str(moved), env=cli_env())
    assert back.returncode == 0, back.stderr
    assert (tmp_path / "back" / "part.gcode").read_bytes() == read_3w(moved).gcode
    original = src.read_bytes()
    (tmp_path / "part.3w").write_bytes(moved.read_bytes())
    for source, existing in ((tmp_path / "part.3w", src), (src, tmp_path / "part.3w")):
        before = existing.read_bytes()
        refused = run_cli("xyz", "convert", str(source), env=cli_env())
        assert refused.returncode == 4, refused.stderr
        assert refused.stderr.strip() == f"fabwire: error: {existing} exists already: name it as DST to replace it, " \
                                          "or give another DST"
        assert existing.read_bytes() == before
    misnamed = tmp_path / "odd.3w"  # G-code under a .3w name: its own name is the output's
    misnamed.write_bytes(original)
    assert run_cli("xyz", "convert", str(misnamed), env=cli_env()).returncode == 4
    assert misnamed.read_bytes() == original
    piped = _piped("xyz", "convert", "-", data=TV_INPUT)
    assert piped.returncode == 2
    assert b"give DST when SRC is standard input" in piped.stderr


@pytest.mark.parametrize(("filament_mm", "shown"), [(3.0, "3.0 mm"), (51.92, "51.9 mm"), (1254.0, "1.25 m")])
def test_convert_and_info_show_filament_alike(tmp_path: Path, filament_mm: float, shown: str) -> None:
    """`convert` and `info` of what it wrote show the filament one way (`units.filament`): millimetres below a metre,
    so 3 mm is never `0.00 m`; the JSON keeps millimetres in `filament_mm`."""
    source = tmp_path / "small.gcode"
    source.write_text(f"; filament used [mm] = {filament_mm}\n; estimated printing time (normal mode) = 1m 0s\n"
                      "G28\nG1 Z0.2 F600\nG1 X10 Y10 E1 F1200\n")
    out = tmp_path / "small.3w"
    converted = run_cli("xyz", "convert", str(source), str(out), env=cli_env(tmp_path))
    assert converted.returncode == 0, converted.stderr
    assert f"filament {shown}," in converted.stdout + converted.stderr
    described = run_cli("xyz", "info", str(out), env=cli_env(tmp_path))
    assert described.returncode == 0, described.stderr
    assert any(line.split()[:1] == ["filament"] and line.split()[1:] == shown.split()
               for line in described.stdout.splitlines())
    as_json = json.loads(run_cli("xyz", "info", str(out), "--json", env=cli_env(tmp_path)).stdout)
    assert as_json["filament_mm"] == pytest.approx(filament_mm)


def test_a_pipe_given_as_a_file_is_read_like_standard_input(tmp_path: Path) -> None:
    """A named pipe (as a shell's `<(…)` gives) and a /proc file cannot be read twice or sought in: they are copied
    first, and every message names them, never the copy."""
    fifo = tmp_path / "piped.gcode"
    os.mkfifo(fifo)
    writer = subprocess.Popen([sys.executable, "-c", f"open({str(fifo)!r}, 'wb').write({TV_INPUT!r})"])
    try:
        done = run_cli("xyz", "convert", str(fifo), str(tmp_path / "out.3w"), env=cli_env())
    finally:
        writer.wait(30)
    assert done.returncode == 0, done.stderr
    assert read_3w(tmp_path / "out.3w").gcode
    proc = run_cli("xyz", "info", "/proc/self/status", env=cli_env())
    assert proc.returncode == 4
    assert proc.stderr.startswith("fabwire: error: /proc/self/status is text, not G-code"), proc.stderr
    made = (tmp_path / "out.3w").read_bytes()
    for args in (("xyz", "info", "-"), ("xyz", "convert", "-", str(tmp_path / "back.gcode"))):
        cut = _piped(*args, data=made[:100])
        assert cut.returncode == 4
        assert cut.stderr.decode().strip() == ("fabwire: error: standard input is truncated: 100 bytes, a .3w has at "
                                               "least 8208")


def test_an_output_not_named_is_never_put_over_a_file_that_appears_meanwhile(tmp_path: Path) -> None:
    """Without DST the output is linked into place, so a file that took the name while converting (another run,
    another program) is kept and the conversion is refused; nothing is left behind."""
    from fabwire.xyz.threew import convert_3w_to_gcode, convert_gcode_file

    src = tmp_path / "part.gcode"
    src.write_bytes(TV_INPUT)
    appeared = tmp_path / "part.3w"
    appeared.write_bytes(b"someone else's")
    with pytest.raises(InputError, match=r"part\.3w exists already"):
        convert_gcode_file(src, appeared, replace=False)
    assert appeared.read_bytes() == b"someone else's"
    made = tmp_path / "made.3w"
    convert_gcode_file(src, made, replace=False)
    back = tmp_path / "back.gcode"
    back.write_bytes(b"mine")
    with pytest.raises(InputError, match=r"back\.gcode exists already"):
        convert_3w_to_gcode(made, back, replace=False)
    assert back.read_bytes() == b"mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["back.gcode", "made.3w", "part.3w", "part.gcode"]
    long_name = tmp_path / ("a" * 253 + ".g")
    long_name.write_bytes(TV_INPUT)
    too_long = run_cli("xyz", "convert", str(long_name), env=cli_env())
    assert too_long.returncode == 4
    assert too_long.stderr.strip().endswith(".3w: File name too long"), too_long.stderr
