"""The ToF unit end to end: emulated sensors served as extension states over a pty, decoded by the
unit driver, fused live; the capture replayed with and without the ToF channel."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from footnav.app.commands.demo import DemoOptions, demo_truth, run_demo
from footnav.app.commands.export import CLEARANCE_COLUMNS, EXPORT_COLUMNS, run_export
from footnav.app.commands.replay import ReplayOptions, run_replay
from footnav.app.config import defaults, load_config
from footnav.pipeline.aiding.tof_types import TofConfig
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.gait.tof_clearance import swing_clearance
from footnav.pipeline.nav_types import NavBatch, concat_batches


def _collector() -> tuple[dict[str, list[NavBatch]], Callable[[str], Callable[[NavBatch], None]]]:
    got: dict[str, list[NavBatch]] = {}

    def make(foot: str) -> Callable[[NavBatch], None]:
        return got.setdefault(foot, []).append

    return got, make


def _clearance_rms_m(opts: DemoOptions, live: NavBatch) -> float:
    """Live clearance against the truth of the same samples (one sample per ms since the first)."""
    truth, _, _ = demo_truth(opts, 0)
    idx = np.rint(live.t_s * 1000).astype(int)
    true_clearance = truth.pos_n_m[idx, 2] - truth.floor_z_m[idx]
    return float(np.sqrt(np.mean((live.clearance_m - true_clearance) ** 2)))


def _replayed(path: Path) -> NavBatch:
    """The capture replayed with a default configuration (the capture's own settings apply)."""
    got, make = _collector()
    assert run_replay(ReplayOptions(path=path, config=defaults(), viewer=False, collect=make)) == 0
    return concat_batches(got["foot"])


def test_demo_with_tof_sensors_live_and_replayed(tmp_path: Path) -> None:
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    got, make = _collector()
    opts = DemoOptions(
        path="line",
        duration_s=25.0,
        viewer=False,
        realtime=math.inf,
        config=cfg,
        collect=make,
        tof=True,
        stance="and",
        axes="gyro-bias-calibrated",
    )
    assert run_demo(opts) == 0
    live = concat_batches(got["foot"])
    assert live.ranges is not None and live.floor_z_m is not None and live.altitude is not None
    assert live.strides is not None and len(live.strides) >= 8
    # every reading the emulator made since the states were switched on reached the navigator through
    # the pty and the decoder (at --pace max the IMU stream runs ahead while the ToF state is switched on)
    t_first = float(live.ranges.t_s[0])
    assert t_first < 5.0
    assert len(live.ranges) > 0.95 * (25.0 - t_first) * 100
    assert np.mean(live.ranges.code == 0) > 0.7
    assert _clearance_rms_m(opts, live) < 0.01
    truth, _, _ = demo_truth(opts, 0)
    idx = np.rint(live.t_s * 1000).astype(int)

    (path,) = tmp_path.glob("*.mcap")
    replayed = _replayed(path)
    # bit for bit, ToF updates and the recorded stance detector ("and") included
    np.testing.assert_array_equal(replayed.pos_n_m, live.pos_n_m)
    np.testing.assert_array_equal(replayed.stance, live.stance)
    np.testing.assert_array_equal(replayed.clearance_m, live.clearance_m)

    got_i, make_i = _collector()
    assert run_replay(ReplayOptions(path=path, config=defaults(), viewer=False, collect=make_i, stance="inertial")) == 0
    assert np.any(concat_batches(got_i["foot"]).stance != live.stance)  # the override is what decides

    # exported to CSV: the live rows, with the clearance columns; the capture's own settings only
    out = tmp_path / "track.csv"
    assert "with clearance" in run_export(path, out, fmt=None, columns=None, profile=None, smooth=False)
    rows = np.genfromtxt(out, delimiter=",", names=True)
    assert rows.dtype.names == EXPORT_COLUMNS + CLEARANCE_COLUMNS
    assert live.ranges is not None
    np.testing.assert_allclose(np.column_stack([rows["x"], rows["y"], rows["z"]]), live.pos_n_m, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(rows["clearance"], live.clearance_m, rtol=1e-8, atol=1e-12)
    swing = swing_clearance(live.t_s, live.pos_n_m, live.stance, live.clearance_m, live.ranges, TofConfig().snap_m)
    np.testing.assert_allclose(rows["clearance_swing"], swing, rtol=1e-8, atol=1e-12)
    with pytest.raises(FootnavError, match="footnav capture"):
        run_export(path, tmp_path / "s.csv", fmt=None, columns=None, profile=None, smooth=True)

    got_n, make_n = _collector()
    assert run_replay(ReplayOptions(path=path, config=defaults(), viewer=False, collect=make_n, tof=False)) == 0
    inertial = concat_batches(got_n["foot"])
    assert inertial.ranges is None and len(inertial) == len(live)
    z_err_tof = np.abs(live.pos_n_m[:, 2] - truth.pos_n_m[idx, 2])
    z_err_ins = np.abs(inertial.pos_n_m[:, 2] - truth.pos_n_m[idx, 2])
    assert z_err_tof[-1000:].mean() < 0.2 * z_err_ins[-1000:].mean()


def test_a_unit_mounted_otherwise_is_configured_in_the_tof_section(tmp_path: Path) -> None:
    """Two sensors where the [tof] section puts them (the emulated unit mounted the same way): fused
    live with that mounting, recorded in the capture, and replayed with it by a default configuration."""
    (tmp_path / "footnav.toml").write_text(
        "[tof]\nlever_b_m = [[0.18, 0.0, 0.06], [-0.10, 0.03, 0.08]]\ndir_b = [[0.0, 0.0, -1.0], [0.0, 0.3, -1.0]]\n"
    )
    cfg = load_config(cwd=tmp_path)
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    got, make = _collector()
    opts = DemoOptions(
        path="line", duration_s=15.0, viewer=False, realtime=math.inf, config=cfg, collect=make, tof=True
    )
    assert run_demo(opts) == 0
    live = concat_batches(got["foot"])
    assert live.ranges is not None and set(live.ranges.sensor.tolist()) == {0, 1}
    assert _clearance_rms_m(opts, live) < 0.01  # 3.5 cm navigated with the default mounting
    (path,) = tmp_path.glob("*.mcap")
    np.testing.assert_array_equal(_replayed(path).pos_n_m, live.pos_n_m)
