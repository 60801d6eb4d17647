"""views/: conversions, the logger thread end to end (real .rrd files read back), sink choice."""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest
import rerun as rr
from footnav.pipeline.gait.events import step_onsets
from footnav.pipeline.nav_types import NavBatch
from footnav.views import convert
from footnav.views.blueprint import build_blueprint
from footnav.views.logger import DEFAULT_ELLIPSOID_EVERY, RerunLogger
from footnav.views.paths import EVENTS, TIMELINE, FootPaths
from footnav.views.sinks import has_display
from numpy.typing import NDArray
from rerun.chunk import RrdReader

RATE_HZ = 1000
DURATION_S = 60.0
BATCH = 10


def quat_to_mat(quat_xyzw: NDArray[np.float64]) -> NDArray[np.float64]:
    x, y, z, w = np.moveaxis(np.asarray(quat_xyzw, dtype=np.float64), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def random_rotations(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return quat_to_mat(q)


def synth_walk(n: int, rng: np.random.Generator) -> NavBatch:
    """n samples of a 1 kHz walk: 1 s gait cycle, 40 % stance, 1.4 m/s, growing covariance."""
    t = np.arange(n) / RATE_HZ
    phase = t % 1.0
    stance = phase < 0.4
    swing = np.clip((phase - 0.4) / 0.6, 0.0, 1.0)
    x = 1.4 * (np.floor(t) + swing)
    clearance = 0.12 * np.sin(np.pi * swing) ** 2
    pos = np.stack([x, 0.1 * np.sin(0.05 * t), 0.05 + clearance], axis=1)
    yaw = 0.05 * t
    quat_wxyz = np.stack([np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)], axis=1)
    rot = random_rotations(rng, n)
    sig2 = (1e-4 + 1e-5 * t)[:, None] * np.array([1.0, 0.5, 0.1])
    cov = np.einsum("nij,nj,nkj->nik", rot, sig2, rot)
    return NavBatch(
        t_s=t,
        pos_n_m=pos,
        vel_n_mps=np.gradient(pos, axis=0) * RATE_HZ,
        quat_nb_wxyz=quat_wxyz,
        pos_cov_n_m2=cov,
        stance=stance,
        detector_stat=np.where(stance, 1e4, 1e7),
        detector_threshold=np.full(n, 3e5),
        clearance_m=clearance,
        host_ns=(t * 1e9).astype(np.int64),
    )


def split(nav: NavBatch, size: int) -> list[NavBatch]:
    return [
        NavBatch(
            t_s=nav.t_s[s : s + size],
            pos_n_m=nav.pos_n_m[s : s + size],
            vel_n_mps=nav.vel_n_mps[s : s + size],
            quat_nb_wxyz=nav.quat_nb_wxyz[s : s + size],
            pos_cov_n_m2=nav.pos_cov_n_m2[s : s + size],
            stance=nav.stance[s : s + size],
            detector_stat=nav.detector_stat[s : s + size],
            detector_threshold=nav.detector_threshold[s : s + size],
            clearance_m=nav.clearance_m[s : s + size],
            host_ns=nav.host_ns[s : s + size],
        )
        for s in range(0, len(nav), size)
    ]


# ---------------------------------------------------------------- convert.py


def test_ellipsoid_axes_of_known_covariance() -> None:
    # σ = (0.3, 0.2, 0.1) along axes rotated 30° about z.
    a = np.deg2rad(30.0)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    cov = rot @ np.diag([0.09, 0.04, 0.01]) @ rot.T
    half, q = convert.cov_ellipsoids(cov[None], sigma_scale=3.0)
    np.testing.assert_allclose(np.sort(half[0]), [0.3, 0.6, 0.9], rtol=1e-12)
    r = quat_to_mat(q[0])
    major = r[:, np.argmax(half[0])]
    assert abs(abs(major @ rot[:, 0]) - 1.0) < 1e-12  # longest axis is the rotated x axis
    assert abs(abs(r[:, np.argmin(half[0])][2]) - 1.0) < 1e-12  # shortest axis is z


def test_ellipsoids_reconstruct_random_covariances() -> None:
    rng = np.random.default_rng(1)
    n = 2000
    rot = random_rotations(rng, n)
    # Include exact 180° rotations (w = 0), where sign-guessing quaternion formulas fail.
    rot[:3] = [
        np.diag([1.0, -1.0, -1.0]),
        [[0, -1, 0], [-1, 0, 0], [0, 0, -1]],
        [[-1, 0, 0], [0, 0, 1], [0, 1, 0]],
    ]
    cov = np.einsum("nij,nj,nkj->nik", rot, rng.uniform(1e-6, 1.0, (n, 3)), rot)
    half, q = convert.cov_ellipsoids(cov, sigma_scale=2.0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    r = quat_to_mat(q)
    back = np.einsum("nij,nj,nkj->nik", r, half**2, r)
    np.testing.assert_allclose(back, 4.0 * cov, atol=1e-10)


def test_degenerate_covariances_give_finite_ellipsoids() -> None:
    cov = np.stack([np.zeros((3, 3)), np.full((3, 3), np.nan), np.diag([1.0, 0.0, -1e-18])])
    half, q = convert.cov_ellipsoids(cov)
    assert np.isfinite(half).all() and np.isfinite(q).all()
    np.testing.assert_array_equal(half[:2], 0.0)


def test_rotmat_quaternion_matches_known_rotation() -> None:
    q_wxyz = np.array([[np.cos(0.4), 0.0, np.sin(0.4), 0.0]])  # 0.8 rad about y
    q_xyzw = convert.quat_wxyz_to_xyzw(q_wxyz)
    np.testing.assert_allclose(q_xyzw, [[0.0, np.sin(0.4), 0.0, np.cos(0.4)]])
    np.testing.assert_allclose(convert.rotmat_to_quat_xyzw(quat_to_mat(q_xyzw)), q_xyzw, atol=1e-15)


def test_pos_sigmas_and_stance_transitions() -> None:
    cov = np.diag([4.0, 9.0, 16.0])[None]
    np.testing.assert_allclose(convert.pos_sigmas(cov), [[2.0, 3.0, 4.0, np.sqrt(29.0)]])
    stance = np.array([True, True, False, False, True])
    np.testing.assert_array_equal(convert.stance_transitions(stance, None), [0, 2, 4])
    np.testing.assert_array_equal(convert.stance_transitions(stance, True), [2, 4])


def test_nav_arrays_shapes() -> None:
    nav = synth_walk(50, np.random.default_rng(0))
    arr = convert.nav_arrays(nav)
    assert arr.pos.shape == (50, 3) and arr.pos.dtype == np.float32
    assert arr.quat_xyzw.shape == (50, 4) and arr.ellipsoids()[1].shape == (50, 4)
    assert arr.pos_sigma.shape == (50, 4) and arr.detector.shape == (50, 2)
    np.testing.assert_array_equal(arr.class_ids, nav.stance.astype(np.uint16))
    cols = {path: (index, c) for path, index, c in convert.nav_columns(arr, FootPaths("left"), ellipsoid_every=1)}
    assert set(cols) >= {"world/left/track", "world/left/pose", "plots/stance/left", "world/left/cov"}
    # Decimation phase follows the running sample index: samples 20, 30, 40 of a batch starting at 13.
    cov = {path: (i, c) for path, i, c in convert.nav_columns(arr, FootPaths(), ellipsoid_every=10, first_index=13)}
    index, cov_cols = cov["world/foot/cov"]
    np.testing.assert_allclose(np.asarray(index.as_arrow_array()).astype(np.int64) / 1e9, nav.t_s[7::10])
    half = {str(c.component_descriptor()): c.as_arrow_array() for c in cov_cols}["Ellipsoids3D:half_sizes"]
    np.testing.assert_allclose(np.array(half.to_pylist())[:, 0, :], arr.ellipsoids()[0][7::10], rtol=1e-6)
    assert "world/foot/cov" not in {path for path, _, _ in convert.nav_columns(arr, FootPaths(), ellipsoid_every=0)}


# ---------------------------------------------------------------- logger.py end to end


def flat(tbl: pa.Table, col: str) -> NDArray[np.float64]:
    return np.asarray(pc.list_flatten(tbl[col]).to_numpy(zero_copy_only=False))


def rows(tbl: pa.Table, col: str, width: int) -> NDArray[np.float64]:
    return np.asarray(pc.list_flatten(pc.list_flatten(tbl[col])).to_numpy(zero_copy_only=False)).reshape(-1, width)


@pytest.fixture(scope="module")
def walk_rrd(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, NavBatch, RerunLogger, float]:
    """60 s of 1 kHz fed in 10-ms batches from a producer thread, saved to a file."""
    path = tmp_path_factory.mktemp("rrd") / "walk.rrd"
    nav = synth_walk(int(DURATION_S * RATE_HZ), np.random.default_rng(7))
    logger = RerunLogger([rr.FileSink(str(path))], recording_id="walk-test-1")
    batches = split(nav, BATCH)

    def produce() -> None:
        logger.log_event("walk started", t_s=0.0)
        for b in batches:
            assert logger.put(b)
        logger.log_truth(nav.pos_n_m + 0.01, t_s=nav.t_s)

    t0 = time.perf_counter()
    producer = threading.Thread(target=produce)
    producer.start()
    producer.join()
    assert logger.close()
    elapsed = time.perf_counter() - t0
    return path, nav, logger, elapsed


def test_logger_writes_every_sample(walk_rrd: tuple[Path, NavBatch, RerunLogger, float]) -> None:
    path, nav, logger, _ = walk_rrd
    n = len(nav)
    assert logger.stats.error is None
    assert logger.stats.samples_dropped == 0 and logger.stats.samples_logged == n
    p = FootPaths()
    store = RrdReader(path).stream().collect()
    for entity, col in [
        (p.track, "Points3D:positions"),
        (p.pose, "Transform3D:translation"),
        (p.stance, "Scalars:scalars"),
        (p.clearance, "Scalars:scalars"),
        (p.pos_sigma, "Scalars:scalars"),
        (p.truth, "Points3D:positions"),
    ]:
        tbl = store.reader(index=TIMELINE, contents=[f"/{entity}"]).to_arrow_table()
        assert tbl.num_rows == n, entity
        assert tbl[f"/{entity}:{col}"].null_count == 0, entity

    tbl = store.reader(
        index=TIMELINE,
        contents=[f"/{p.track}", f"/{p.stance}", f"/{p.clearance}", f"/{p.pos_sigma}", f"/{p.pose}"],
    ).to_arrow_table()
    t_s = pc.divide(pc.cast(tbl[TIMELINE], pa.int64()), 1e9).to_numpy()
    np.testing.assert_allclose(t_s, nav.t_s, atol=1e-9)
    np.testing.assert_allclose(rows(tbl, f"/{p.track}:Points3D:positions", 3), nav.pos_n_m, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(rows(tbl, f"/{p.pose}:Transform3D:quaternion", 4),
                               convert.quat_wxyz_to_xyzw(nav.quat_nb_wxyz), atol=1e-6)  # fmt: skip
    np.testing.assert_array_equal(flat(tbl, f"/{p.stance}:Scalars:scalars").astype(bool), nav.stance)
    np.testing.assert_allclose(flat(tbl, f"/{p.clearance}:Scalars:scalars"), nav.clearance_m, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        flat(tbl, f"/{p.pos_sigma}:Scalars:scalars").reshape(-1, 4), convert.pos_sigmas(nav.pos_cov_n_m2)
    )
    class_ids = flat(tbl, f"/{p.track}:Points3D:class_ids")
    np.testing.assert_array_equal(class_ids.astype(bool), nav.stance)


def test_logger_ellipsoids_are_decimated_and_match_covariance(
    walk_rrd: tuple[Path, NavBatch, RerunLogger, float],
) -> None:
    path, nav, _, _ = walk_rrd
    every = DEFAULT_ELLIPSOID_EVERY
    p = FootPaths()
    store = RrdReader(path).stream().collect()
    tbl = store.reader(index=TIMELINE, contents=[f"/{p.cov}"]).to_arrow_table()
    assert tbl.num_rows == len(nav) // every  # the same samples whatever the batch borders
    t_s = pc.divide(pc.cast(tbl[TIMELINE], pa.int64()), 1e9).to_numpy()
    np.testing.assert_allclose(t_s, nav.t_s[::every], atol=1e-9)
    half = rows(tbl, f"/{p.cov}:Ellipsoids3D:half_sizes", 3)
    r = quat_to_mat(rows(tbl, f"/{p.cov}:Ellipsoids3D:quaternions", 4))
    back = np.einsum("nij,nj,nkj->nik", r, half**2, r)
    scale = convert.DEFAULT_SIGMA_SCALE**2
    np.testing.assert_allclose(back, scale * nav.pos_cov_n_m2[::every], rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(rows(tbl, f"/{p.cov}:Ellipsoids3D:centers", 3), nav.pos_n_m[::every], atol=1e-6)


def test_logger_recording_identity_blueprint_and_events(
    walk_rrd: tuple[Path, NavBatch, RerunLogger, float],
) -> None:
    path, nav, _, _ = walk_rrd
    reader = RrdReader(path)
    recs = reader.recordings()
    assert [(r.application_id, r.recording_id) for r in recs] == [("footnav", "walk-test-1")]
    assert len(reader.blueprints()) == 1
    store = reader.stream().collect()
    events = store.reader(index=TIMELINE, contents=[f"/{EVENTS}"]).to_arrow_table()
    assert pc.list_flatten(events[f"/{EVENTS}:TextLog:text"]).to_pylist() == ["walk started"]
    gait = store.reader(index=TIMELINE, contents=[f"/{FootPaths().gait}"]).to_arrow_table()
    n_changes = int(np.count_nonzero(np.diff(nav.stance.astype(int)))) + 1
    assert gait.num_rows == n_changes  # one row per stance/swing transition, across batch borders
    static = store.reader(index=None, contents="/world/**").to_arrow_table()
    assert "/world:ViewCoordinates:xyz" in static.column_names


def test_logger_throughput(walk_rrd: tuple[Path, NavBatch, RerunLogger, float]) -> None:
    path, nav, logger, elapsed = walk_rrd
    size_mb = path.stat().st_size / 1e6
    rate = len(nav) / elapsed
    print(f"\n60 s @ 1 kHz: {size_mb:.1f} MB .rrd, {rate:,.0f} samples/s end to end, "
          f"{logger.stats.sends} sends, {logger.stats.send_seconds:.2f} s in send")  # fmt: skip
    assert rate > 10 * RATE_HZ  # comfortably faster than real time
    assert size_mb < 30


def test_put_never_blocks_and_counts_drops(tmp_path: Path) -> None:
    path = tmp_path / "tiny.rrd"
    nav = synth_walk(2000, np.random.default_rng(3))
    logger = RerunLogger([rr.FileSink(str(path))], recording_id="drop-test", max_queued_samples=500)
    t0 = time.perf_counter()
    accepted = [logger.put(b) for b in split(nav, 100)]
    assert time.perf_counter() - t0 < 0.5
    assert logger.close()
    dropped = logger.stats.samples_dropped
    assert dropped == 100 * accepted.count(False)
    assert logger.stats.samples_logged + dropped == len(nav)
    assert not logger.put(nav)  # after close: refused and counted
    if dropped:
        store = RrdReader(path).stream().collect()
        events = store.reader(index=TIMELINE, contents=[f"/{EVENTS}"]).to_arrow_table()
        assert any("fell behind" in s for s in pc.list_flatten(events[f"/{EVENTS}:TextLog:text"]).to_pylist())


def test_put_with_timeout_applies_backpressure_without_loss(tmp_path: Path) -> None:
    path = tmp_path / "bp.rrd"
    nav = synth_walk(5000, np.random.default_rng(4))
    with RerunLogger([rr.FileSink(str(path))], recording_id="bp-test", max_queued_samples=300) as logger:
        for b in split(nav, 100):
            assert logger.put(b, timeout_s=5.0)
    assert logger.stats.samples_dropped == 0 and logger.stats.samples_logged == len(nav)
    tbl = RrdReader(path).stream().collect().reader(index=TIMELINE, contents=[f"/{FootPaths().stance}"])
    assert tbl.to_arrow_table().num_rows == len(nav)


def test_the_truth_error_is_thinned_on_the_sessions_samples_whatever_the_batches(tmp_path: Path) -> None:
    """Every ``series_every``-th sample of the session, as the speed plot, not of each batch."""
    path = tmp_path / "truth.rrd"
    nav = synth_walk(1000, np.random.default_rng(3))
    # no flush period, a pause between batches: the logger takes them one by one (mostly; it may join some)
    logger = RerunLogger([rr.FileSink(str(path))], recording_id="truth", truth=True, series_every=10, flush_period_s=0)
    with logger:
        logger.log_truth(nav.pos_n_m + 0.01, t_s=nav.t_s)
        for b in split(nav, 7):
            assert logger.put(b, timeout_s=5.0)
            time.sleep(0.002)
    store = RrdReader(path).stream().collect()

    def times(entity: str) -> list[int]:
        return store.reader(index=TIMELINE, contents=[entity]).to_arrow_table()[TIMELINE].to_pylist()  # type: ignore[no-any-return]

    paths = FootPaths()
    assert len(times(paths.truth_error)) == 100 and times(paths.truth_error) == times(paths.speed)
    assert logger.stats.sends > 10  # the batches were logged apart (else this would test nothing)


def test_two_feet_paths_and_unknown_foot(tmp_path: Path) -> None:
    path = tmp_path / "feet.rrd"
    nav = synth_walk(300, np.random.default_rng(5))
    with RerunLogger([rr.FileSink(str(path))], recording_id="feet", feet=("left", "right")) as logger:
        assert logger.put(nav, foot="left") and logger.put(nav, foot="right")
        with pytest.raises(ValueError, match="not declared"):
            logger.put(nav)
    store = RrdReader(path).stream().collect()
    for foot in ("left", "right"):
        tbl = store.reader(index=TIMELINE, contents=[f"/world/{foot}/track"]).to_arrow_table()
        assert tbl.num_rows == len(nav)


def test_no_sinks_is_an_error() -> None:
    with pytest.raises(ValueError, match="at least one sink"):
        RerunLogger([], recording_id="x")


def test_blueprint_builds_for_two_feet() -> None:
    assert build_blueprint(("left", "right")) is not None
    with pytest.raises(ValueError):
        FootPaths("a/b")


# ---------------------------------------------------------------- sinks.py


def test_without_a_display_the_session_is_saved_and_says_how_to_open_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from footnav.views.outputs import open_session_views
    from footnav.views.sinks import rerun_command

    monkeypatch.chdir(tmp_path)
    env: dict[str, str] = {}
    if has_display(env):
        pytest.skip("macOS and Windows always report a display")

    def kinds(save: Path | None, want_viewer: bool) -> tuple[list[str], str]:
        views, notes = open_session_views(
            save=save, want_viewer=want_viewer, recording_id="no-display", notice=print, environ=env
        )
        out = [] if views is None else [o.kind for o in views.outputs]
        if views is not None:
            assert views.close() == []
        return out, "; ".join(notes)

    out, desc = kinds(None, True)
    (saved,) = tmp_path.glob("footnav-*.rrd")
    assert out == ["recording file"] and "no display" in desc and f"saving to {saved}" in desc
    exe = rerun_command()
    assert f"`{exe} {saved.name}` on a machine with a display" in desc  # relative to the working directory
    assert f"in a browser: `{exe} --web-viewer --bind 127.0.0.1 {saved.name}`" in desc
    out, desc = kinds(tmp_path / "y.rrd", False)
    assert out == ["recording file"] and "no display" not in desc and str(tmp_path / "y.rrd") in desc
    assert kinds(None, False) == ([], "Rerun output off (no viewer, no file)")


def test_default_recording_names_do_not_clash(tmp_path: Path) -> None:
    from datetime import datetime

    from footnav.views.sinks import default_save_path

    now = datetime(2026, 12, 8, 3, 4, 5)
    first = default_save_path(now, tmp_path)
    assert first.name == "footnav-20261208-030405.rrd"
    first.touch()  # another session of the same second
    assert default_save_path(now, tmp_path).name == "footnav-20261208-030405-2.rrd"


def test_the_hint_names_the_rerun_of_this_install(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the environment activated ``rerun`` is not on PATH: the hint gives the command's path."""
    from footnav.views.sinks import open_hint, rerun_command, rerun_script

    exe = rerun_script()
    assert exe.is_file()  # installed with rerun-sdk
    monkeypatch.setenv("PATH", str(exe.parent))
    assert rerun_command() == "rerun"
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    assert rerun_command() == str(exe)
    monkeypatch.chdir(exe.parent.parent)
    assert rerun_command() == str(Path(exe.parent.name) / exe.name)
    assert open_hint(Path("a b.rrd"), {"DISPLAY": ":0"}) == f"view it with `{rerun_command()} 'a b.rrd'`"


def test_step_onsets_floor_ellipses_and_heading() -> None:
    stance = np.array([True, True, False, False, True, True, False, True])
    np.testing.assert_array_equal(step_onsets(stance, None), [4, 7])  # standing at the start is no step
    np.testing.assert_array_equal(step_onsets(stance, False), [0, 4, 7])
    a = np.deg2rad(30.0)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    cov = rot @ np.diag([0.09, 0.04, 0.01]) @ rot.T
    half, q = convert.floor_ellipses(cov[None], sigma_scale=3.0)
    np.testing.assert_allclose(half[0, :2], [0.9, 0.6], rtol=1e-12)
    assert half[0, 2] == convert.STEP_ELLIPSE_HALF_THICKNESS_M
    r = quat_to_mat(q[0])
    assert abs(abs(r[:, 0] @ rot[:, 0]) - 1.0) < 1e-12 and abs(r[2, 2] - 1.0) < 1e-12  # about z only
    yaw = np.deg2rad([0.0, 90.0, -135.0])
    q_wxyz = np.stack([np.cos(yaw / 2), 0 * yaw, 0 * yaw, np.sin(yaw / 2)], axis=1)
    np.testing.assert_allclose(convert.heading_deg(q_wxyz), [0.0, 90.0, -135.0], atol=1e-12)


# ---------------------------------------------------------------- the viewer's private folder


@pytest.mark.skipif(sys.platform != "linux", reason="a bogus DISPLAY only stops the viewer on Linux")
def test_a_viewer_that_fails_to_start_leaves_no_private_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The real viewer binary cannot open a window on a display that does not exist: whether it was
    started by a session or alone, its private folder is gone once the start failed."""
    import tempfile

    from footnav.views.outputs import open_session_views
    from footnav.views.sinks import ViewerStartError, spawn_viewer

    temp = tmp_path / "temp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))  # where private_folder() makes its folders
    env = {**os.environ, "DISPLAY": ":987", "WAYLAND_DISPLAY": ""}
    views, notes = open_session_views(
        save=tmp_path / "f.rrd", want_viewer=True, recording_id="no-window", notice=print, environ=env
    )
    assert views is not None and [o.kind for o in views.outputs] == ["recording file"]
    assert any("viewer not started" in n for n in notes), notes
    assert list(temp.iterdir()) == []
    assert views.close() == []
    with pytest.raises(ViewerStartError):
        spawn_viewer(env=env)  # a folder of its own
    assert list(temp.iterdir()) == []


@pytest.mark.skipif(sys.platform != "linux", reason="the /bin/sh wrapper; the viewer found in /proc")
def test_a_viewer_open_at_the_session_end_removes_its_folder_when_it_exits(tmp_path: Path) -> None:
    """A Rerun viewer process (the real binary, serving its web viewer: it runs without a display)
    started through ``remove_folder_after`` as ``spawn_viewer`` starts it: the session's end leaves its
    folder while it runs; when the viewer alone exits (as when its window is closed), the folder goes."""
    import subprocess

    from footnav.views.outputs import Output, SessionViews
    from footnav.views.rerun_env import private_folder, remove_folder_after, rerun_environment
    from footnav.views.sinks import LOOPBACK, _free_loopback_port, _port_open, viewer_binary

    folder = private_folder()
    grpc_port, web_port = _free_loopback_port(), _free_loopback_port()
    cmd = [str(viewer_binary()), "--serve-web", "--bind", LOOPBACK, "--port", str(grpc_port),
           "--web-viewer-port", str(web_port)]  # fmt: skip
    proc = subprocess.Popen(
        remove_folder_after(cmd, folder),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
        env=rerun_environment(folder),
    )
    try:
        deadline = time.monotonic() + 15.0
        while not _port_open(grpc_port) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _port_open(grpc_port) and proc.poll() is None
        url = f"rerun+http://{LOOPBACK}:{grpc_port}/proxy"
        logger = RerunLogger([rr.GrpcSink(url)], recording_id="folder-test")
        views = SessionViews([Output("viewer", f"pid {proc.pid}", logger, proc, folder=folder)], notice=print)
        views.put(synth_walk(500, np.random.default_rng(3)))
        assert views.close() == []
        assert proc.poll() is None and (folder / "config" / "rerun" / "analytics.json").is_file()  # left to it
        (viewer_pid,) = (int(p) for p in Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split())
        os.kill(viewer_pid, 15)  # the viewer alone, not its wrapper
        assert proc.wait(15) == 128 + 15  # the wrapper exits with the viewer's code
        assert not folder.exists()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, 9)
            proc.wait(5)
        if folder.exists():
            import shutil

            shutil.rmtree(folder)
