"""A unit's calibration file applied automatically: the emulated miscalibrated unit walks on the pty
(real serial code), is asked its MCU id, and its calibration corrects the stream before the navigator;
the capture records the exchange and replay applies the same calibration, bit for bit."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from footnav.app.calibration_store import save_calibration
from footnav.app.commands.demo import DemoOptions, demo_truth, run_demo
from footnav.app.commands.replay import ReplayOptions, run_replay
from footnav.app.config import CLI, Config, defaults
from footnav.app.experiments.calibration import calibrate_emulated
from footnav.device.emulator.sensors.icosahedron import MISCALIBRATED_MCU_ID, Miscalibration
from footnav.device.files.capture import iter_capture, summarize_capture
from footnav.device.protocol import commands as protocol
from footnav.pipeline.nav_types import NavBatch, concat_batches

DURATION_S = 20.0


def collector() -> tuple[list[NavBatch], Callable[[str], Callable[[NavBatch], None]]]:
    got: list[NavBatch] = []
    return got, lambda foot: got.append


def config(tmp: Path, cal_dir: Path, *, apply: bool = True) -> Config:
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp), CLI)
    cfg.set("calibration.dir", str(cal_dir), CLI)
    cfg.set("calibration.apply", apply, CLI)
    return cfg


def walk(cfg: Config) -> tuple[NavBatch, float]:
    got, make = collector()
    opts = DemoOptions(
        duration_s=DURATION_S, viewer=False, realtime=math.inf, config=cfg, collect=make, miscalibrated=True
    )
    assert run_demo(opts) == 0
    nav = concat_batches(got)
    truth, _, _ = demo_truth(opts, 0)
    idx = np.rint(nav.t_s * truth.rate_hz).astype(np.int64)
    return nav, float(np.linalg.norm(nav.pos_n_m[-1] - truth.pos_n_m[idx[-1]]))


def tx_commands(path: Path) -> list[int]:
    parser = protocol.CommandParser(protocol.CommandSet.V2015)
    return [c.cmd_id for m in iter_capture(path) if getattr(m, "direction", "") == "tx" for c in parser.feed(m.data)]


def test_calibration_applied_live_and_in_replay(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cal_dir = tmp_path / "cal"
    cal, _ = calibrate_emulated(Miscalibration(), grade="mpu6500x4", seed=3)
    cal_path = save_calibration(cal_dir, MISCALIBRATED_MCU_ID, cal, source="test")

    nav_cal, err_cal = walk(config(tmp_path / "with", cal_dir))
    out = capsys.readouterr().err
    assert f"applying calibration {cal_path}" in out and "reference temperature" in out
    _, err_raw = walk(config(tmp_path / "without", tmp_path / "empty"))
    assert "applying calibration" not in capsys.readouterr().err
    assert err_raw > 0.15 and err_cal < err_raw / 5, (err_cal, err_raw)

    (cap_with,) = (tmp_path / "with").glob("*.mcap")
    (cap_without,) = (tmp_path / "without").glob("*.mcap")
    events = summarize_capture(cap_with).events["foot"]
    (mcu,) = [e for e in events if e["event"] == "mcu_id"]
    assert mcu["mcu_id"] == MISCALIBRATED_MCU_ID.hex() and mcu["calibration"] == str(cal_path)
    assert protocol.CMD_MCU_ID in tx_commands(cap_with)
    # no calibration file anywhere: the unit is not even asked (sessions talk to it as before)
    assert protocol.CMD_MCU_ID not in tx_commands(cap_without)

    runs = (
        (config(tmp_path, cal_dir), nav_cal),
        (config(tmp_path, tmp_path / "empty"), nav_cal),  # the capture keeps the calibration it applied
        (config(tmp_path, cal_dir, apply=False), None),
    )
    for cfg, expected in runs:
        got, make = collector()
        assert run_replay(ReplayOptions(path=cap_with, config=cfg, viewer=False, collect=make)) == 0
        replayed = concat_batches(got)
        if expected is not None:
            np.testing.assert_array_equal(replayed.pos_n_m, expected.pos_n_m)  # bit for bit
            assert f"applying calibration {cal_path}" in capsys.readouterr().err
        else:
            assert len(replayed) == len(nav_cal)
            assert not np.array_equal(replayed.pos_n_m, nav_cal.pos_n_m)


def test_the_calibration_file_of_another_unit_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A file renamed or copied to this unit's name: its own MCU id says whose it is."""
    cal_dir = tmp_path / "cal"
    cal, _ = calibrate_emulated(Miscalibration(), grade="mpu6500x4", seed=3)
    other = save_calibration(cal_dir, b"another unit", cal, source="test")
    other.rename(cal_dir / f"{MISCALIBRATED_MCU_ID.hex()}.json")
    _, err = walk(config(tmp_path, cal_dir))
    said = capsys.readouterr().err
    assert f"is the calibration of another unit (MCU id {b'another unit'.hex()}" in said and "applying" not in said
    assert err > 0.15  # navigated uncalibrated


def test_a_malformed_calibration_file_is_reported_and_the_session_goes_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cal_dir = tmp_path / "cal"
    cal_dir.mkdir()
    (cal_dir / f"{MISCALIBRATED_MCU_ID.hex()}.json").write_text(json.dumps({"format": "something else"}))
    _, err = walk(config(tmp_path, cal_dir))
    assert "is not a footnav calibration file" in capsys.readouterr().err
    assert err > 0.15
