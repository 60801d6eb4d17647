"""The console script's end (``footnav.app.cli.run``): after a command that writes plain files the process
skips the interpreter's teardown, and loses nothing by it: exit handlers run, the streams are flushed, the
exit code and the files are those of :func:`footnav.app.cli.main`."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from footnav.app.cli import main

TRIAL = Path("pyshoe-vicon") / "2017-11-27-11-12-44.mat"

SCRIPT = textwrap.dedent(
    """
    import atexit, os, sys, threading
    from footnav.app.cli import run

    class Teardown:  # said only if the interpreter tears its objects down
        def __del__(self):
            sys.stdout.write("teardown\\n")

    teardown = Teardown()
    atexit.register(lambda: print("exit handler ran"))
    assert "numpy" not in sys.modules  # so OpenBLAS reads the thread count run() sets
    atexit.register(lambda: print("OPENBLAS_NUM_THREADS", os.environ.get("OPENBLAS_NUM_THREADS")))
    if sys.argv[1] == "--with-thread":  # another thread alive: the interpreter ends as usual
        threading.Thread(target=threading.Event().wait, daemon=True).start()
        sys.argv.pop(1)
    print("before", end="", flush=False)  # unflushed text in stdout's buffer
    run()
    """
)


def _console(tmp_path: Path, *args: str, **env_vars: str) -> subprocess.CompletedProcess[str]:
    script = tmp_path / "console.py"
    script.write_text(SCRIPT, encoding="utf-8")
    unset = ("PYTHONUNBUFFERED", "OPENBLAS_NUM_THREADS")  # stdout keeps its buffer; footnav chooses the threads
    env = {k: v for k, v in os.environ.items() if k not in unset} | env_vars
    return subprocess.run(
        [sys.executable, str(script), *args], capture_output=True, text=True, timeout=300, check=False, env=env
    )


def test_export_ends_without_teardown_and_loses_nothing(shared_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "console.csv"
    proc = _console(tmp_path, "export", str(shared_data / TRIAL), "-o", str(out))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("beforewrote ") and str(out) in lines[0]
    assert lines[-2:] == ["OPENBLAS_NUM_THREADS 1", "exit handler ran"] and "teardown" not in proc.stdout
    reference = tmp_path / "main.csv"
    assert main(["export", str(shared_data / TRIAL), "-o", str(reference)]) == 0
    assert out.read_bytes() == reference.read_bytes()


def test_a_failed_export_keeps_its_exit_code_and_message(tmp_path: Path) -> None:
    missing = tmp_path / "missing.csv"
    proc = _console(tmp_path, "export", str(missing), "-o", str(tmp_path / "out.csv"))
    assert proc.returncode == 2
    assert proc.stderr.startswith("footnav: error:") and str(missing) in proc.stderr
    assert proc.stdout == "before" + "OPENBLAS_NUM_THREADS 1\nexit handler ran\n"


def test_config_ends_without_teardown_unless_another_thread_runs(tmp_path: Path) -> None:
    quick = _console(tmp_path, "config")
    assert quick.returncode == 0, quick.stderr
    assert quick.stdout.startswith("before") and quick.stdout.endswith("exit handler ran\n")
    assert "teardown" not in quick.stdout
    usual = _console(tmp_path, "--with-thread", "config")
    assert usual.returncode == 0, usual.stderr
    assert usual.stdout.removeprefix("before") == quick.stdout.removeprefix("before") + "teardown\n"


def test_a_thread_count_the_user_set_for_openblas_is_kept(tmp_path: Path) -> None:
    proc = _console(tmp_path, "config", OPENBLAS_NUM_THREADS="2")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.endswith("OPENBLAS_NUM_THREADS 2\nexit handler ran\n")


MAIN = "import sys; from footnav.app.cli import main; sys.exit(main(sys.argv[1:]))"


def _still_walk_csv(path: Path, n: int = 2000) -> Path:
    """``n`` samples at 200 Hz of a unit at rest, as a generic CSV."""
    t = np.arange(n) / 200.0
    imu = np.column_stack([t, np.zeros(n), np.zeros(n), np.full(n, 9.81), np.zeros((n, 3))])
    np.savetxt(path, imu, delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.9g")
    return path


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (Linux)")
@pytest.mark.parametrize("command", ["export", "config"])
def test_a_failed_write_to_stdout_ends_as_main_does(tmp_path: Path, command: str) -> None:
    """stdout on a full disk: the export's one line fails when flushed at the end, config's long text while
    printing; either way the exit code and the message are those of :func:`main`, never success."""
    script = tmp_path / "console.py"
    script.write_text(SCRIPT.replace('print("before", end="", flush=False)', ""), encoding="utf-8")
    args = ["config"]
    if command == "export":
        args = ["export", str(_still_walk_csv(tmp_path / "walk.csv")), "-o", str(tmp_path / "track.csv")]
    ends = []
    for argv in ([str(script), *args], ["-c", MAIN, *args]):
        with open("/dev/full", "w") as full:
            proc = subprocess.run(
                [sys.executable, *argv], stdout=full, stderr=subprocess.PIPE, text=True, timeout=300, check=False
            )
        ends.append((proc.returncode, "No space left on device" in proc.stderr))
    assert ends[0] == ends[1] and ends[0][0] != 0 and ends[0][1]


def test_a_closed_stdout_ends_as_main_does(tmp_path: Path) -> None:
    """Started with descriptor 1 closed (``sys.stdout`` is None): the export is written and the exit code is 0."""
    script = tmp_path / "console.py"
    script.write_text(SCRIPT.replace('print("before", end="", flush=False)', ""), encoding="utf-8")
    walk, track = _still_walk_csv(tmp_path / "walk.csv"), tmp_path / "track.csv"
    proc = subprocess.run(
        [sys.executable, str(script), "export", str(walk), "-o", str(track)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=300, check=False,
        preexec_fn=lambda: os.close(1),
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert track.read_text().count("\n") == 1 + 2000
