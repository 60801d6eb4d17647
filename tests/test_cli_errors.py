"""Bad input at the command line: one line saying what happened and what to try, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
import termios
import tty
from pathlib import Path

import numpy as np
import pytest

from device.emulator.pty_server import PtyShoeServer


def _footnav(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "DISPLAY": "", "WAYLAND_DISPLAY": ""}
    return subprocess.run(
        [sys.executable, "-m", "app", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        check=False,
    )


def _assert_one_line_error(proc: subprocess.CompletedProcess[str], *needles: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if line.startswith("footnav: error:")]
    assert len(errors) == 1, proc.stderr
    for needle in needles:
        assert needle in errors[0]


def test_missing_port(tmp_path: Path) -> None:
    proc = _footnav("live", "--port", "/dev/ttyNOPE42", "--no-viewer")
    _assert_one_line_error(proc, "/dev/ttyNOPE42", "plugged in")


def test_busy_port(tmp_path: Path) -> None:
    n = 10
    with PtyShoeServer(np.arange(n) / 1000.0, np.zeros((n, 3)), np.zeros((n, 3))) as server:
        import serial

        holder = serial.Serial(server.port, exclusive=True)
        try:
            proc = _footnav("live", "--port", server.port, "--no-viewer")
        finally:
            holder.close()
    _assert_one_line_error(proc, server.port, "busy")


def test_silent_unit(tmp_path: Path) -> None:
    master, slave = os.openpty()  # a serial device that never answers
    tty.setraw(slave, termios.TCSANOW)
    try:
        proc = _footnav("live", "--port", os.ttyname(slave), "--no-viewer")
    finally:
        os.close(master)
        os.close(slave)
    _assert_one_line_error(proc, "no answer", "start command")


@pytest.mark.parametrize("args", [["demo", "--duration", "-3"], ["demo", "--path", "moon"]])
def test_bad_arguments_are_usage_errors(args: list[str]) -> None:
    proc = _footnav(*args)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "usage:" in proc.stderr
