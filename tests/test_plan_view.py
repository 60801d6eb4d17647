"""The plan view and the stride table: plan axes (north up), ellipse contours at the stated sigma, a
grid that grows with the walk and never shrinks, strides between footfalls with the detector's
flicker left out, and both read back from a demo's ``.rrd``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
from footnav.pipeline.nav_types import NavBatch
from footnav.views import plan
from footnav.views.strides import StrideTable
from rerun.chunk import RrdReader


def test_plan_points_have_north_up_and_ellipses_lie_on_the_sigma_contour() -> None:
    np.testing.assert_array_equal(plan.to_plan(np.array([[1.0, 2.0, 3.0]])), [[1.0, -2.0]])
    rng = np.random.default_rng(0)
    a = rng.normal(size=(5, 2, 2))
    cov = a @ np.swapaxes(a, 1, 2) + 0.01 * np.eye(2)
    center = rng.normal(size=(5, 2))
    strips = plan.ellipse_strips(center, cov, sigma_scale=3.0)
    assert strips.shape == (5, plan.ELLIPSE_VERTICES, 2)
    d = strips.astype(np.float64) - np.column_stack([center[:, 0], -center[:, 1]])[:, None, :]
    d[..., 1] *= -1.0  # back to navigation axes
    mahalanobis = np.einsum("kmi,kij,kmj->km", d, np.linalg.inv(cov), d)
    np.testing.assert_allclose(mahalanobis, 9.0, rtol=1e-4)  # every vertex on the 3-sigma contour


def test_the_grid_covers_the_walk_on_whole_labels_and_only_grows() -> None:
    first = plan.grid_bounds(np.array([[0.0, 0.0], [18.0, -9.0]], dtype=np.float32), None)
    assert first == (-5.0, 20.0, -15.0, 5.0)
    assert plan.grid_bounds(np.array([[1.0, -1.0]], dtype=np.float32), first) is None  # inside: unchanged
    grown = plan.grid_bounds(np.array([[30.0, 0.0]], dtype=np.float32), first)
    assert grown == (-5.0, 35.0, -15.0, 5.0)  # the other foot's extent is kept
    labels = dict(plan.grid_archetypes(grown))[f"{plan.PLAN}/grid/labels"]
    assert labels is not None


def _nav(t_s: np.ndarray, x_m: np.ndarray, clearance_m: np.ndarray, onsets: list[int]) -> NavBatch:
    n = t_s.size
    pos = np.column_stack([x_m, np.zeros(n), clearance_m])
    z = np.zeros(n)
    return NavBatch(
        t_s=t_s, pos_n_m=pos, vel_n_mps=np.zeros((n, 3)), quat_nb_wxyz=np.tile([1.0, 0, 0, 0], (n, 1)),
        pos_cov_n_m2=np.zeros((n, 3, 3)), stance=z.astype(bool), detector_stat=z, detector_threshold=z,
        clearance_m=clearance_m, host_ns=z.astype(np.int64), step_onsets=np.asarray(onsets, dtype=np.intp),
    )  # fmt: skip


def test_strides_run_between_footfalls_and_a_flicker_is_no_stride() -> None:
    t = np.arange(400) / 100.0
    x = 1.3 * np.floor(t)  # a footfall every second, 1.3 m on
    clearance = 0.12 * np.sin(np.pi * (t % 1.0)) ** 2
    table = StrideTable(("foot",))
    # footfalls at 1, 2 and 3 s; the detector flickers 70 ms after the one at 2 s
    assert not table.update("foot", _nav(t[:150], x[:150], clearance[:150], [100]))
    assert table.update("foot", _nav(t[150:], x[150:], clearance[150:], [50, 57, 150]))
    rows = table._feet["foot"].strides
    assert [round(s.length_m, 6) for s in rows] == [1.3, 1.3]
    assert [round(s.duration_s, 6) for s in rows] == [1.0, 1.0]
    np.testing.assert_allclose([s.peak_m for s in rows], 0.12, atol=1e-3)
    md = table.markdown()
    assert "2 strides" in md and "| **mean** | 1.30 | 1.00 | 1.30 | 0.120 |" in md


def test_a_demo_recording_holds_the_plan_view_and_the_stride_table(tmp_path: Path) -> None:
    rrd = tmp_path / "d.rrd"
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "demo", "--duration", "20", "--pace", "max", "--save", str(rrd),
         "--no-viewer", "--sessions", str(tmp_path)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    store = RrdReader(rrd).stream().collect()

    def rows(entity: str):  # type: ignore[no-untyped-def]
        return store.reader(index="imu_time", contents=[entity]).to_arrow_table()

    track = rows("/world/foot/track")
    steps3d = rows("/world/foot/steps")
    steps = rows("/plan/foot/steps")
    assert steps.num_rows == steps3d.num_rows > 10  # a plan marker per step
    xyz = np.asarray(pc.list_flatten(pc.list_flatten(steps3d["/world/foot/steps:Points3D:positions"])).to_numpy())
    xy = np.asarray(pc.list_flatten(pc.list_flatten(steps["/plan/foot/steps:Points2D:positions"])).to_numpy())
    np.testing.assert_allclose(xy.reshape(-1, 2), xyz.reshape(-1, 3)[:, :2] * [1.0, -1.0], atol=1e-5)
    line = rows("/plan/foot/line")
    assert line.num_rows >= 1 and track.num_rows == 20_000
    assert rows("/plan/grid/labels").num_rows >= 1
    text = rows("/strides")["/strides:TextDocument:text"].to_pylist()[-1][0]
    assert "strides" in text and "| **mean** |" in text


def test_a_pyshoe_replay_draws_its_truth_in_the_plan_and_plots_the_error(tmp_path: Path, shared_data: Path) -> None:
    """The motion capture beside the estimate, from above, and the horizontal error over time: small
    (this trial's ATE-2D is a few centimetres), never NaN once both exist."""
    rrd = tmp_path / "p.rrd"
    trial = shared_data / "pyshoe-vicon" / "2017-11-22-11-22-03.mat"
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "replay", str(trial), "--no-viewer", "--save", str(rrd)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    store = RrdReader(rrd).stream().collect()
    error = store.reader(index="imu_time", contents=["/plots/truth_error/foot"]).to_arrow_table()
    values = np.asarray(pc.list_flatten(error["/plots/truth_error/foot:Scalars:scalars"]).to_numpy())
    assert values.size > 100 and np.all(np.isfinite(values))
    # (a few samples near 13.5 s reach 0.8 m: a glitch of the estimate or the capture at one spot)
    assert np.median(values) < 0.1 and np.percentile(values, 95) < 0.15, np.percentile(values, [50, 95])
    truth = store.reader(index="imu_time", contents=["/plan/truth/foot"]).to_arrow_table()
    assert truth.num_rows == 1


def test_replay_with_smooth_draws_the_smoothed_track_beside_the_causal_one(tmp_path: Path, shared_data: Path) -> None:
    rrd = tmp_path / "s.rrd"
    trial = shared_data / "pyshoe-vicon" / "2017-11-22-11-22-03.mat"
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "replay", str(trial), "--smooth", "--no-viewer", "--save", str(rrd)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0 and "drawn in purple beside the causal filter's track" in proc.stderr, proc.stderr
    store = RrdReader(rrd).stream().collect()
    causal = store.reader(index="imu_time", contents=["/world/foot/track"]).to_arrow_table()
    smoothed = store.reader(index="imu_time", contents=["/world/foot/smoothed"]).to_arrow_table()
    assert causal.num_rows == 6490 and smoothed.num_rows == 649  # every sample; every 10th smoothed
    c = np.asarray(pc.list_flatten(pc.list_flatten(causal["/world/foot/track:Points3D:positions"])).to_numpy())
    s = np.asarray(pc.list_flatten(pc.list_flatten(smoothed["/world/foot/smoothed:Points3D:positions"])).to_numpy())
    gap = np.linalg.norm(c.reshape(-1, 3)[::10][:649] - s.reshape(-1, 3), axis=1)
    assert 0.0 < np.median(gap) < 0.2  # two estimates of one walk, not the same one twice
