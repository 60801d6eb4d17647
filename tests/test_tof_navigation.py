"""ToF aiding in the navigator, on emulated recordings: the issue's figures, the side-by-side run
without the ToF channel, streaming against batch, and bad input (time-outs, invalid statuses, step
edges, reflective floors)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from footnav.app.experiments import tof as exp
from footnav.device.emulator.motion.floors import floor_of
from footnav.device.emulator.sensors.tof import TofSensorModel
from footnav.pipeline.aiding.tof import LEVEL_STATES, TofAiding
from footnav.pipeline.aiding.tof_types import RangeBatch, RangeOutputs, TofConfig
from footnav.pipeline.gait.tof_clearance import SwingClearanceTracker, swing_clearance
from footnav.pipeline.navigation.navigator import NavConfig, Navigator, navigate
from footnav.pipeline.navigation.profiles import get_profile
from footnav.pipeline.samples import ImuBatch


@pytest.fixture(scope="module")
def walk70() -> exp.Recording:
    return exp.record("rectangle", 70.0, seed=1)


@pytest.fixture(scope="module")
def stairs70() -> exp.Recording:
    return exp.record("stairs", 70.0, seed=1)


def test_70s_walk_meets_the_issue_figures(walk70: exp.Recording) -> None:
    """The platform's unit (gyroscope bias calibrated, datasheet scale and cross-axis errors left):
    ZUPT alone 29.3 cm at footfalls, ToF 0.13 cm (234x lower), horizontal unchanged."""
    zupt, tof = exp.compare(walk70)
    assert tof.clearance_rms_m <= 0.01
    assert tof.z_stance_rms_m <= 0.0015  # 1.3 mm
    assert zupt.z_stance_rms_m >= 5.0 * tof.z_stance_rms_m
    assert tof.xy_stance_rms_m <= zupt.xy_stance_rms_m
    assert tof.readings["used"] > 0.75 * len(walk70.ranges)
    assert zupt.readings == {}


@pytest.mark.xfail(
    strict=True,
    reason="with no axis errors at all (noise and biases only) ZUPT alone loses only 4.2 mm at footfalls on this "
    "walk, and ToF at its noise floor (1.1 mm) is 3.9x lower; seeds 1-8 1.4-21x (5x with 5 of 8). Real "
    "recordings drift 50-100x more than such a unit (README Accuracy)",
)
def test_70s_walk_vertical_error_5x_lower_on_a_unit_without_axis_errors() -> None:
    zupt, tof = exp.compare(exp.record("rectangle", 70.0, seed=1, axes="none"))
    assert zupt.z_stance_rms_m >= 5.0 * tof.z_stance_rms_m


def test_stairs_floor_is_followed_and_never_gone_through(stairs70: exp.Recording) -> None:
    config = NavConfig(profile=get_profile("mpu6500x4"))
    t = stairs70.truth
    nav, _ = navigate(t.t_s, stairs70.acc_b_mps2, stairs70.gyr_b_radps, t.rate_hz, config, ranges=stairs70.ranges)
    assert nav is not None and nav.floor_z_m is not None and nav.ranges is not None
    first = len(t) - len(nav)
    floor_err = nav.floor_z_m - t.floor_z_m[first:]
    assert np.mean(np.abs(floor_err) < 0.03) > 0.98  # the tread under the IMU, 24 risers up and down
    assert np.min(nav.pos_n_m[:, 2] - t.floor_z_m[first:]) > -0.03  # never through the floor
    codes = exp._counts(nav)
    assert codes["step_edge"] > 500  # rays that saw the next tread in swing: gated, counted


@pytest.mark.xfail(
    strict=True,
    reason="not met live on stairs: clearance 1.14 cm RMS (1.02-1.39 cm with seeds 1-8; 1.02-1.17 cm with no axis "
    "errors); near each step edge the floor under the IMU is known only to lie between the last hits on either "
    "side (3-10 cm apart in swing). From the whole swing's hits (replay, evaluation) it is met: next test",
)
def test_stairs_clearance_within_1cm_live(stairs70: exp.Recording) -> None:
    _, tof = exp.compare(stairs70)
    assert tof.clearance_rms_m <= 0.01


def test_stairs_clearance_within_1cm_from_the_whole_swing(stairs70: exp.Recording) -> None:
    """footnav.pipeline.gait.tof_clearance: 0.86 cm on this walk (0.86-0.94 cm with seeds 1-8, either emulated unit)."""
    _, tof = exp.compare(stairs70)
    assert tof.swing_clearance_rms_m <= 0.01
    assert tof.swing_clearance_rms_m < 0.8 * tof.clearance_rms_m


def test_stairs_clearance_near_step_edges_is_interpolated_and_learned(stairs70: exp.Recording) -> None:
    """Regression guard: on the unit without axis errors 1.51 cm RMS with the nearest hit's floor, 1.20 cm
    interpolated between the hits on either side of an edge, 1.08 cm with the edges learned in earlier swings;
    1.14 cm on this walk's unit."""
    _, tof = exp.compare(stairs70)
    assert tof.clearance_rms_m <= 0.012


@pytest.mark.parametrize("seed", range(1, 9))
def test_stairs_vertical_error_5x_lower(seed: int) -> None:
    """6.7-21x with seeds 1-8 (0.33-1.32 cm against 2.5-21 cm): the treads are floor-level states of
    the filter, so what it learns later (the accelerometer bias at the landing's turn) corrects the
    treads already placed (footnav.pipeline.aiding.tof). Placed once, at the state's height, they were
    1.3-27x (seed 3 worst: 1.91 cm against 2.54 cm)."""
    zupt, tof = exp.compare(exp.record("stairs", 70.0, seed=seed))
    assert zupt.z_stance_rms_m >= 5.0 * tof.z_stance_rms_m


def test_treads_placed_on_a_climb_are_corrected_by_what_the_filter_learns_later() -> None:
    """Seed 3's accelerometer has a 10 mg forward bias: on the straight climb it cannot be told from
    pitch and puts each tread 0.2-1.1 cm off when placed; the landing's turn reveals it, and the
    treads, states of the filter, end within 0.21 cm of the true ones."""
    rec = exp.record("stairs", 70.0, seed=3)
    t = rec.truth
    nav = Navigator(NavConfig(profile=get_profile("mpu6500x4")), t.rate_hz)
    nav.add_ranges(rec.ranges)
    placed: dict[int, float] = {}
    for a in range(0, len(t), 200):
        idx = np.arange(a, min(len(t), a + 200))
        nav.process(ImuBatch(t.t_s[idx], rec.acc_b_mps2[idx], rec.gyr_b_radps[idx], idx, np.zeros(idx.size, np.int64)))
        for k, z in enumerate(nav.tof.levels_z_m):
            placed.setdefault(k, z)
    treads = floor_of("stairs").levels_z_m
    final = np.asarray(nav.tof.levels_z_m[1:])
    true = treads[np.argmin(np.abs(treads[None, :] - final[:, None]), axis=1)]
    placed_err = np.asarray([placed[k] for k in range(1, len(final) + 1)]) - true
    assert len(final) >= 10 and nav.tof.counts.get("levels_left_state") == 0
    assert np.max(np.abs(placed_err)) > 0.008
    assert np.max(np.abs(final - true)) < 0.003


def test_level_states_are_bounded_and_the_oldest_leaves_with_its_height() -> None:
    """TofAiding on its own: each new level clones the state's height error into a level state (the
    covariance grows by one state at a time); past LEVEL_STATES the level stood on longest ago leaves
    the state and keeps its height."""
    aid = TofAiding(TofConfig())
    rng = np.random.default_rng(1)
    x = np.zeros(16)
    x[6] = 1.0
    A = rng.normal(0.0, 0.01, (15, 15))
    P = A @ A.T
    for k in range(LEVEL_STATES + 4):
        x, P = aid.reserve(x, P)
        x[2] = 0.16 * (k + 1)
        aid._stance_t0 = float(k)
        i = aid._level_state[aid._new_level(x, P)]
        np.testing.assert_array_equal(np.delete(P[i], i), np.delete(P[2], i))
        assert P[i, i] == pytest.approx(P[2, 2] + aid.config.new_level_sigma_m**2) and x[i + 1] == x[2]
    assert P.shape == (15 + LEVEL_STATES, 15 + LEVEL_STATES) and x.shape == (16 + LEVEL_STATES,)
    states = aid._level_state[1:]
    assert states[:4] == [-1] * 4 and sorted(states[4:]) == list(range(15, 15 + LEVEL_STATES))
    assert aid.counts.get("levels_left_state") == 4
    np.testing.assert_allclose(aid.levels_z_m[1:5], [0.16, 0.32, 0.48, 0.64])
    aid.sync(x)  # the levels still states read their heights from the state
    assert aid.levels_z_m[-1] == x[aid._level_state[-1] + 1]
    # with the readings unused there are no level states at all
    off = TofAiding(TofConfig(use=False))
    assert off.reserve(x[:16], P[:15, :15])[1].shape == (15, 15)


def test_without_the_tof_channel_the_result_is_the_inertial_one(walk70: exp.Recording) -> None:
    """Readings decoded and shown but not used: the batch is split at every reading, and the result
    is the inertial-only one to the last bit (so the side-by-side gain is the ToF's alone)."""
    t = walk70.truth
    inertial = NavConfig(stance_levels=False)  # with a ToF unit its floor levels replace the stance levels
    plain, _ = navigate(t.t_s, walk70.acc_b_mps2, walk70.gyr_b_radps, t.rate_hz, inertial)
    shown, _ = navigate(
        t.t_s, walk70.acc_b_mps2, walk70.gyr_b_radps, t.rate_hz, inertial, ranges=walk70.ranges,
        tof=TofConfig(use=False),
    )  # fmt: skip
    assert plain is not None and shown is not None and shown.ranges is not None
    np.testing.assert_array_equal(shown.pos_n_m, plain.pos_n_m)
    np.testing.assert_array_equal(shown.quat_nb_wxyz, plain.quat_nb_wxyz)
    assert plain.ranges is None and len(shown.ranges) > 6000


def test_streaming_in_small_batches_matches_the_batch_run(walk70: exp.Recording) -> None:
    """Live: 5 ms reads, each read's ToF readings queued before its IMU samples, as the session does."""
    t, rec = walk70.truth, walk70
    n = 40_000
    batch_nav, _ = navigate(t.t_s[:n], rec.acc_b_mps2[:n], rec.gyr_b_radps[:n], t.rate_hz, ranges=rec.ranges)
    nav = Navigator(NavConfig(), t.rate_hz)
    outs = []
    for a in range(0, n, 5):
        b = min(a + 5, n)
        sel = (rec.ranges.t_s >= (t.t_s[a - 1] if a else -1.0)) & (rec.ranges.t_s < t.t_s[b - 1])
        nav.add_ranges(rec.ranges.select(sel))
        idx = np.arange(a, b)
        out = nav.process(
            ImuBatch(t.t_s[idx], rec.acc_b_mps2[idx], rec.gyr_b_radps[idx], idx, np.zeros(b - a, np.int64))
        )
        if out is not None:
            outs.append(out)
    pos = np.concatenate([o.pos_n_m for o in outs])
    assert batch_nav is not None and pos.shape == batch_nav.pos_n_m.shape
    assert np.max(np.abs(pos - batch_nav.pos_n_m)) < 2e-3
    assert nav.tof.counts.get("late") > 0  # readings that came in the read after their sample


def _bad_recording(path: str, seed: int = 4) -> tuple[exp.Recording, RangeBatch]:
    sensors = TofSensorModel(seed=9, timeout_rate=0.2, spurious_rate=0.1)
    rec = exp.record(path, 70.0, seed=seed, sensors=sensors)
    # a reading from a sensor that does not exist, a sensor error, a zero range with a valid status
    extra = RangeBatch(
        t_s=np.array([10.0001, 10.0002, 20.0001]),
        sensor=np.array([7, 1, 1], dtype=np.int64),
        range_m=np.array([0.05, np.nan, 0.0]),
        status=np.array([0, 4, 0], dtype=np.uint8),
    )
    return rec, RangeBatch.concat([rec.ranges, extra])


def test_bad_input_is_gated_counted_and_never_pulls_through_the_floor() -> None:
    """Flat floor, 20 % time-outs, 10 % reflections (ranges 5-50 cm too long), odd readings."""
    rec, ranges = _bad_recording("rectangle")
    t = rec.truth
    zupt, _ = navigate(t.t_s, rec.acc_b_mps2, rec.gyr_b_radps, t.rate_hz, NavConfig(stance_levels=False))
    nav, _ = navigate(t.t_s, rec.acc_b_mps2, rec.gyr_b_radps, t.rate_hz, ranges=ranges)
    assert nav is not None and nav.ranges is not None and zupt is not None
    counts = exp._counts(nav)
    assert counts["timeout"] > 0.15 * len(rec.ranges)
    assert counts["outlier"] + counts["step_edge"] > 0.05 * len(rec.ranges)  # the reflections
    assert counts["unknown_sensor"] == 1 and counts["sensor_error"] >= 1
    first = len(t) - len(nav)
    assert np.min(nav.pos_n_m[:, 2] - t.floor_z_m[first:]) > -0.01  # never through the floor
    assert np.min(nav.clearance_m) > -0.01
    still = t.stance[first:]
    err_z = nav.pos_n_m[still, 2] - t.pos_n_m[first:][still, 2]
    err_z0 = zupt.pos_n_m[still, 2] - t.pos_n_m[first:][still, 2]
    assert np.sqrt(np.mean(err_z**2)) < 0.2 * np.sqrt(np.mean(err_z0**2))


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_bad_input_on_stairs_is_no_worse_than_zupt_alone(seed: int) -> None:
    """Stairs, 20 % time-outs, 10 % reflections, odd readings: the vertical error at footfalls (walks 1-5:
    0.76 vs 13.89, 0.97 vs 13.66, 0.84 vs 2.51, 1.42 vs 21.23, 1.10 vs 18.80 cm with ZUPT alone; 0.45-1.42
    cm with walks 1-8). With no axis errors (ZUPT alone then loses 0.24-2.1 cm) walk 7 is worse than ZUPT
    alone: 0.30 vs 0.24 cm (the other seven 0.25-1.06 cm, below it)."""
    rec, ranges = _bad_recording("stairs", seed)
    t = rec.truth
    zupt, _ = navigate(t.t_s, rec.acc_b_mps2, rec.gyr_b_radps, t.rate_hz, NavConfig(stance_levels=False))
    nav, _ = navigate(t.t_s, rec.acc_b_mps2, rec.gyr_b_radps, t.rate_hz, ranges=ranges)
    assert nav is not None and zupt is not None
    first = len(t) - len(nav)
    still = t.stance[first:]
    err_z = nav.pos_n_m[still, 2] - t.pos_n_m[first:][still, 2]
    err_z0 = zupt.pos_n_m[still, 2] - t.pos_n_m[first:][still, 2]
    assert np.sqrt(np.mean(err_z**2)) <= np.sqrt(np.mean(err_z0**2))


def test_whole_swing_clearance_streamed_equals_the_whole_recordings(stairs70: exp.Recording) -> None:
    """SwingClearanceTracker fed in 50-sample batches returns every sample once, in order, with the
    values of swing_clearance over the whole recording; a swing's come once its margin has passed."""
    t = stairs70.truth
    nav, _ = navigate(
        t.t_s,
        stairs70.acc_b_mps2,
        stairs70.gyr_b_radps,
        t.rate_hz,
        NavConfig(profile=get_profile("mpu6500x4")),
        ranges=stairs70.ranges,
    )
    assert nav is not None and nav.ranges is not None
    snap = TofConfig().snap_m
    whole = swing_clearance(nav.t_s, nav.pos_n_m, nav.stance, nav.clearance_m, nav.ranges, snap)
    tracker = SwingClearanceTracker(snap)
    r = nav.ranges
    times, values, lags = [], [], []
    for a in range(0, len(nav), 50):
        b = min(a + 50, len(nav))
        sel = (r.t_s > (nav.t_s[a - 1] if a else -np.inf)) & (r.t_s <= nav.t_s[b - 1])
        part = dataclasses.replace(r, **{f.name: getattr(r, f.name)[sel] for f in dataclasses.fields(r)})
        t_out, c_out = tracker.update(nav.t_s[a:b], nav.pos_n_m[a:b], nav.stance[a:b], nav.clearance_m[a:b], part)
        times.append(t_out)
        values.append(c_out)
        if t_out.size:
            lags.append(nav.t_s[b - 1] - t_out[-1])
    t_out, c_out = tracker.finish()
    times.append(t_out)
    values.append(c_out)
    np.testing.assert_array_equal(np.concatenate(times), nav.t_s)
    np.testing.assert_allclose(np.concatenate(values), whole, rtol=0, atol=1e-12)
    assert max(lags) < 1.5  # a swing's values within a swing and the margin (0.25 s) of its start


@pytest.mark.parametrize("seed", [1, 4])
def test_bad_input_on_stairs_whole_swing_clearance_is_no_worse_than_live(seed: int) -> None:
    """Reflections agree with each other more often among a whole swing's hits than among the live
    lookup's last 12: a hit counts there only with MIN_SUPPORT hits at its height (walks 1-5: 3.05-4.80
    cm live, 2.24-3.72 cm from the whole swing; 4.80-5.89 cm counting a hit with one other agreeing)."""
    rec, ranges = _bad_recording("stairs", seed)
    t = rec.truth
    nav, _ = navigate(t.t_s, rec.acc_b_mps2, rec.gyr_b_radps, t.rate_hz, ranges=ranges)
    assert nav is not None and nav.ranges is not None
    first = len(t) - len(nav)
    true_clearance = t.pos_n_m[first:, 2] - t.floor_z_m[first:]
    swing = swing_clearance(nav.t_s, nav.pos_n_m, nav.stance, nav.clearance_m, nav.ranges, TofConfig().snap_m)
    rms_live = np.sqrt(np.mean((nav.clearance_m - true_clearance) ** 2))
    rms_swing = np.sqrt(np.mean((swing - true_clearance) ** 2))
    assert rms_swing <= rms_live
    stance = nav.stance
    np.testing.assert_array_equal(swing[stance], nav.clearance_m[stance])  # stance keeps its decided floor


def test_experiment_command_prints_the_side_by_side_table(capsys: pytest.CaptureFixture[str]) -> None:
    from footnav.app.cli import main

    assert main(["experiment", "tof", "--duration", "15"]) == 0
    out = capsys.readouterr().out.splitlines()
    rows = [line for line in out if line.startswith(("rectangle", "line", "stairs"))]
    assert len(rows) == 6  # three walks, each with and without the ToF channel
    assert sum("ZUPT+ToF" in r and "used" in r for r in rows) == 3
    assert sum("lower with ToF" in line for line in out) == 3


def test_whole_swing_clearance_passes_a_long_run_without_stance_through_at_once() -> None:
    """A foot carried (no stance for 5 s): after MAX_SWING_S its samples come back in the call that
    brought them, with their live clearance; the buffers do not grow; the next real swing is looked up."""
    rate = 100.0
    t = np.arange(0, 8.0, 1 / rate)
    stance = np.ones(t.size, dtype=bool)
    stance[100:600] = False  # 5 s carried
    stance[700:740] = False  # then one 0.4 s swing over a raised surface seen by the sensors
    pos = np.zeros((t.size, 3))
    pos[:, 0] = np.linspace(0.0, 4.0, t.size)
    pos[:, 2] = 0.05
    live = np.full(t.size, 0.05)
    r_t = np.arange(0.0, 8.0, 0.01) + 0.005
    hit = np.column_stack([np.interp(r_t, t, pos[:, 0]), np.zeros(r_t.size), np.where(r_t > 7.2, 0.02, 0.0)])
    ranges = RangeOutputs(
        r_t,
        np.zeros(r_t.size, np.int64),
        np.zeros(r_t.size, np.uint8),
        np.full(r_t.size, 0.05),
        np.zeros(r_t.size, np.int64),
        np.zeros(r_t.size),
        np.zeros(r_t.size),
        hit,
        np.zeros(r_t.size, bool),
    )
    tracker = SwingClearanceTracker(0.004)
    out_t, out_c = [], []
    for a in range(0, t.size, 10):
        sel = (r_t > (t[a - 1] if a else -1.0)) & (r_t <= t[a + 9])
        part = dataclasses.replace(ranges, **{f.name: getattr(ranges, f.name)[sel] for f in dataclasses.fields(ranges)})
        got_t, got_c = tracker.update(t[a : a + 10], pos[a : a + 10], stance[a : a + 10], live[a : a + 10], part)
        if 350 <= a < 590:  # well into the carried run: this call's samples come back at once
            np.testing.assert_array_equal(got_t, t[a : a + 10])
            assert len(tracker._t) == 0
        out_t.append(got_t)
        out_c.append(got_c)
    got_t, got_c = tracker.finish()
    out_t.append(got_t)
    out_c.append(got_c)
    c = np.concatenate(out_c)
    np.testing.assert_array_equal(np.concatenate(out_t), t)
    np.testing.assert_array_equal(c[:700], live[:700])  # the carried run keeps its live values
    assert np.all(c[725:740] < 0.04)  # the short swing's later part: 2 cm up, looked up from its hits
