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
from footnav.device.emulator.serving.pty import PtyShoeServer

NO_BLUETOOTH = {"DBUS_SYSTEM_BUS_ADDRESS": "unix:path=/nonexistent/footnav-test-bus"}
"""Forces bleak's BlueZ backend onto a system bus that is not there: no Bluetooth stack."""


def _footnav(*args: str, timeout: float = 60, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "DISPLAY": "", "WAYLAND_DISPLAY": "", **(env or {})}
    return subprocess.run(
        [sys.executable, "-m", "footnav.app", *args],
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
    # Never having streamed, the unit is the start command's time-out to report, not a stall to restart.
    assert "stopped streaming" not in proc.stderr and "reconnecting" not in proc.stderr


@pytest.mark.parametrize("args", [["demo", "--duration", "-3"], ["demo", "--path", "moon"]])
def test_bad_arguments_are_usage_errors(args: list[str]) -> None:
    proc = _footnav(*args)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "usage:" in proc.stderr


@pytest.mark.skipif(sys.platform != "linux", reason="forces the no-D-Bus path of bleak's BlueZ backend")
def test_live_over_ble_without_a_bluetooth_stack_is_one_line(tmp_path: Path) -> None:
    proc = _footnav("live", "--ble", "FOOT-L", "--no-viewer", "--sessions", str(tmp_path), env=NO_BLUETOOTH)
    _assert_one_line_error(proc, "no Bluetooth stack available", "BlueZ")
    assert "1 kHz over BLE" not in proc.stderr  # 250 Hz is the BLE default
    proc = _footnav("live", "--ble", "FOOT-L", "--rate-divider", "0", "--no-viewer", "--sessions", str(tmp_path),
                    env=NO_BLUETOOTH)  # fmt: skip
    _assert_one_line_error(proc, "no Bluetooth stack available")
    assert "footnav: warning: 1 kHz over BLE" in proc.stderr  # asked for explicitly: allowed, with a warning
    assert not list(tmp_path.glob("*.mcap"))  # no unit ever answered: no capture left behind


@pytest.mark.skipif(sys.platform != "linux", reason="forces the no-D-Bus path of bleak's BlueZ backend")
def test_scan_without_a_bluetooth_stack_says_so_and_lists_serial_ports() -> None:
    proc = _footnav("scan", "--timeout", "0.5", env=NO_BLUETOOTH)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stdout.splitlines()
    ble = [line for line in lines if line.startswith("ble ")]
    assert len(ble) == 1 and ble[0].split(None, 1)[1].startswith("no Bluetooth stack available"), proc.stdout
    assert any(line.startswith("serial ") for line in lines)  # the serial part is there all the same
