"""Fuzzing the command line (hypothesis): argument lists built from the parser itself, every command's
options with good and bad values, run through ``footnav.app.cli.main`` in this process.

Whatever the arguments, the command works or says in a line what is wrong: exit code 0, 1 or 2, no
traceback, no exception out of ``main``. The I/O cannot reach hardware or leave the test's folder:
ports that do not exist or are not serial ports, files in a temporary folder (missing, empty,
garbage, a small CSV, a real capture), no Bluetooth (``--ble`` is left out, as are ``scan`` and
``experiment``, which only scan or compute), no viewer (``--web`` is left out; without a display a
demo saves its ``.rrd`` in the temporary folder) and short runs (``--duration`` at most 2 s, paces
and replay speeds of 100x or more).

Briefly in the suite; at length on demand::

    FOOTNAV_FUZZ_EXAMPLES=2000 .venv/bin/python -m pytest tests/test_fuzz_cli.py
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from footnav.app.cli import main
from footnav.app.parser import build_parser
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_fuzz_inputs import demo_capture

EXAMPLES = int(os.environ.get("FOOTNAV_FUZZ_EXAMPLES", "150"))
FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize="FOOTNAV_FUZZ_EXAMPLES" not in os.environ,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow, HealthCheck.data_too_large],
)

COMMANDS = ("demo", "live", "calibrate", "replay", "export", "evaluate", "config")
"""Every command but ``scan`` (it scans for BLE units) and ``experiment`` (minutes of computing)."""
LEFT_OUT = {"--ble", "--web", "--demo", "--help"}
"""Options that would reach a radio, serve a viewer, or run the emulated calibration (minutes at 10x)."""
FILES = ("missing.csv", "empty.csv", "junk.bin", "walk.csv", "capture.mcap", "folder", "/proc/footnav-x.rrd")
"""Input and output names, in the example's folder (but the last: a place nothing can be written)."""
NUMBERS = ("0", "1", "-1", "1.5", "1e9", "nan", "inf", "abc", "", "0x0F", "2x", "max")
"""Values tried where an option takes a number or a name (good ones and bad ones)."""
VALUES: dict[str, tuple[str, ...]] = {
    "--duration": ("0.5", "2", "0", "-3", "1e9", "nan", "abc"),
    "--pace": ("max", "100x", "1000", "0", "-1x", "zz"),
    "demo --speed": ("1.4", "1.2", "1.8", "1.0", "abc"),
    "replay --speed": ("max", "100x", "0x", "abc"),
    "--port": ("/dev/ttyNOPE0", "/dev/null", "junk.bin", "missing.csv"),
    "--left": ("/dev/ttyNOPE1", "/dev/null"),
    "--right": ("/dev/ttyNOPE2", "junk.bin"),
    "--imu-mask": ("0x0F", "3", "0", "0x100", "zz", "-1"),
    "--columns": ("time=t,acc=ax;ay;az:g", "time=t:ms", "acc=a;b", "bogus", "time=foo", "gyr=x;y;z:furlong/s"),
    "--profile": ("generic", "mpu6500x4", "nope"),
    "--start": ("0", "0.5", "1e9", "-1", "abc"),
    "--end": ("1", "0.2", "inf", "abc"),
    "--hold": ("0.5", "0", "abc"),
    "--seed": ("0", "7", "-1", "4294967296", "abc"),
    "--lever-arm": ("0.01", "0", "-0.02", "nan", "abc"),
    "--board-lever-arm": ("0.01", "0.03", "inf"),
}
"""Values per option (``COMMAND --option`` for one command's), instead of :data:`NUMBERS`."""
PATH_OPTIONS = ("--save", "--sessions", "--config", "--capture", "--output", "--steps", "FILE", "INPUT", "PATH")


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {name: sub.choices[name] for name in COMMANDS}


def _values(command: str, action: argparse.Action) -> st.SearchStrategy[str]:
    name = action.option_strings[-1] if action.option_strings else str(action.metavar)
    if name in PATH_OPTIONS:
        return st.sampled_from(FILES)
    if f"{command} {name}" in VALUES:
        return st.sampled_from(VALUES[f"{command} {name}"])
    if name in VALUES:
        return st.sampled_from(VALUES[name])
    if action.choices is not None:
        return st.sampled_from([str(c) for c in action.choices] + ["bogus"])
    return st.sampled_from(NUMBERS)


@st.composite
def command_lines(draw: st.DrawFn) -> list[str]:
    """``[command, options..., positionals...]`` for one of :data:`COMMANDS`."""
    commands = _commands()
    command = draw(st.sampled_from(COMMANDS))
    parser = commands[command]
    argv = [command]
    actions = [a for a in parser._actions if not set(a.option_strings) & LEFT_OUT and a.dest != "help"]
    options = [a for a in actions if a.option_strings]
    for action in draw(st.lists(st.sampled_from(options), max_size=6, unique_by=id)):
        argv.append(action.option_strings[-1])
        if action.nargs == 0:
            continue
        count = action.nargs if isinstance(action.nargs, int) else 1
        argv.extend(draw(_values(command, action)) for _ in range(count))
    for action in (a for a in actions if not a.option_strings):
        count = draw(st.integers(1, 2)) if action.nargs == "+" else 1
        argv.extend(draw(_values(command, action)) for _ in range(count))
    if command in ("demo", "live", "replay") and draw(st.booleans()):
        argv.append("--no-viewer")
    if command == "calibrate" and not {"--port", "--capture"} & set(argv):
        argv += ["--port", "/dev/ttyNOPE3"]  # its source is required; --ble and --demo are left out
    if command == "demo" and "--duration" not in argv:
        argv += ["--duration", "1"]  # not the 60 s default
    if command == "demo" and "--pace" not in argv:
        argv += ["--pace", "max"]  # not real time
    if command == "calibrate":
        argv.append("--no-capture")
    return draw(st.sampled_from([[], ["-v"]])) + argv


@contextlib.contextmanager
def _scratch(folder: Path) -> Iterator[None]:
    """Work in ``folder`` (the relative names of :data:`FILES`), with no display (no viewer starts)."""
    saved = {k: os.environ.pop(k) for k in ("DISPLAY", "WAYLAND_DISPLAY") if k in os.environ}
    try:
        with contextlib.chdir(folder):
            yield
    finally:
        os.environ.update(saved)


def _fill(folder: Path) -> None:
    (folder / "empty.csv").write_bytes(b"")
    (folder / "junk.bin").write_bytes(bytes(range(256)) * 4)
    (folder / "folder").mkdir()
    rows = [f"{k / 100:.2f},0.01,-0.02,9.81,0.001,0.002,-0.001" for k in range(200)]
    (folder / "walk.csv").write_text("t,ax,ay,az,gx,gy,gz\n" + "\n".join(rows) + "\n")
    (folder / "capture.mcap").write_bytes(demo_capture())


@pytest.mark.slow
@FUZZ
@given(argv=command_lines())
def test_any_command_line_works_or_says_what_is_wrong_in_a_line(argv: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        _fill(folder)
        err = io.StringIO()
        with _scratch(folder), contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse's usage errors
                code = exc.code if isinstance(exc.code, int) else 2
        text = err.getvalue()
        assert "Traceback" not in text, text
        assert code in (0, 1, 2), (code, text)
        if code == 2:
            assert "error:" in text or "calibration not saved" in text, text
