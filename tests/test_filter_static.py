"""The navigator on a unit at rest: alignment, bias observability, honest covariance, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from footnav.pipeline.errors import InputFormatError
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation.alignment import align_from_still
from footnav.pipeline.navigation.batches import NO_CLIPPED_RATES
from footnav.pipeline.navigation.navigator import NavConfig, navigate
from footnav.pipeline.navigation.quaternion import quat_from_euler_zyx, quat_to_mat, yaw_of

RATE_HZ = 1000.0


def _still(n: int, roll: float, pitch: float, gyr_bias: np.ndarray, seed: int = 0):
    rng = np.random.default_rng(seed)
    mat_nb = quat_to_mat(quat_from_euler_zyx(roll, pitch, 0.0))
    f_b = mat_nb.T @ np.array([0.0, 0.0, 9.80665])
    acc = f_b + rng.normal(0, 0.02, (n, 3))
    gyr = gyr_bias + rng.normal(0, 0.002, (n, 3))
    return np.arange(n) / RATE_HZ, acc, gyr


@pytest.mark.parametrize(("roll", "pitch"), [(0.0, 0.0), (0.4, -0.3), (math.pi - 0.2, 0.1)])
def test_alignment_recovers_tilt(roll: float, pitch: float) -> None:
    _, acc, gyr = _still(500, roll, pitch, np.zeros(3))
    al = align_from_still(acc, gyr)
    # gravity direction in body frame must match
    np.testing.assert_allclose(
        quat_to_mat(al.quat_nb_wxyz).T[:, 2], quat_to_mat(quat_from_euler_zyx(roll, pitch, 0))[2], atol=3e-3
    )
    assert abs(yaw_of(al.quat_nb_wxyz)[0]) < 1e-12
    assert al.gravity_mps2 == pytest.approx(9.80665, abs=0.01)


def test_alignment_rejects_wrong_units() -> None:
    _, acc, gyr = _still(500, 0.1, 0.1, np.zeros(3))
    with pytest.raises(InputFormatError, match="m/s²"):
        align_from_still(acc / 9.80665, gyr)  # samples in g


def test_rest_stays_put_and_bias_is_estimated() -> None:
    bias = np.radians([0.3, -0.2, 0.25])  # z bias only observable through zero-angular-rate updates
    t, acc, gyr = _still(30_000, 0.2, -0.1, bias)
    out, stats = navigate(t, acc, gyr, RATE_HZ)
    assert out is not None
    assert stats.samples_out == 30_000 and stats.samples_before_alignment == 0
    assert np.abs(out.pos_n_m).max() < 1e-3
    assert np.abs(out.vel_n_mps[-1]).max() < 1e-3
    assert out.stance[20:].all()  # stance is declared after 20 ms below the threshold
    sigma = np.sqrt(np.diagonal(out.pos_cov_n_m2, axis1=1, axis2=2))
    assert (np.diff(sigma[:, 0]) >= -1e-12).all() or sigma[-1, 0] < 0.01  # grows slowly or stays small
    assert np.all(np.linalg.eigvalsh(out.pos_cov_n_m2[-1]) > 0)


def test_accelerometer_bias_along_gravity_is_estimated_against_the_configured_gravity() -> None:
    """At rest the accelerometer reads gravity plus its bias: against a known gravity (standard by
    default, ``NavConfig.gravity_mps2``) the zero-velocity updates see the bias along gravity and the
    filter estimates it; taking |f| at rest for gravity (0) hides it in g, and the bias state stays at 0."""
    from footnav.pipeline.navigation.navigator import Navigator
    from footnav.pipeline.samples import ImuBatch

    t, acc, gyr = _still(10_000, 0.3, -0.2, np.zeros(3))
    mat_nb = quat_to_mat(quat_from_euler_zyx(0.3, -0.2, 0.0))
    bias_b = 4e-3 * 9.80665 * mat_nb.T[:, 2]  # 4 mg along gravity
    n = t.size
    estimates = []
    for gravity in (9.80665, 0.0):
        nav = Navigator(NavConfig(gravity_mps2=gravity), RATE_HZ)
        out = nav.process(ImuBatch(t, acc + bias_b, gyr, np.arange(n), np.zeros(n, dtype=np.int64)))
        state = nav.state
        assert out is not None and state is not None and np.abs(out.pos_n_m).max() < 1e-3
        estimates.append(state[10:13] @ mat_nb.T[:, 2])  # the bias estimate along gravity
    known, measured = estimates
    assert known == pytest.approx(4e-3 * 9.80665, rel=0.05)
    assert abs(measured) < 0.05 * 4e-3 * 9.80665


def test_gyro_bias_is_tracked_after_alignment() -> None:
    # alignment sees no bias; the bias then steps (e.g. warm-up) and ZARU must find it
    # With the mpu6500x4 profile's bias random walk the steady-state gain gives a time constant of
    # about 28 s, so after 100 s the residual of the step is a few percent.
    t, acc, gyr = _still(105_000, 0.0, 0.0, np.zeros(3))
    step = np.radians([0.0, 0.0, 0.2])
    gyr[5000:] += step
    from footnav.pipeline.navigation.navigator import Navigator
    from footnav.pipeline.samples import ImuBatch

    nav = Navigator(NavConfig(), RATE_HZ)
    n = t.size
    nav.process(ImuBatch(t, acc, gyr, np.arange(n), np.zeros(n, dtype=np.int64)))
    state = nav.state
    assert state is not None
    np.testing.assert_allclose(state[13:16], step, atol=np.radians(0.01))


def test_slow_turn_of_a_still_foot_is_rotation_not_gyro_bias() -> None:
    """A foot that stays still but turns slowly (a pivot, 0.8 °/s for 3 s) is turned, not taken for a
    gyro bias: the zero-rate gate tests the rate against the gyroscope's noise (``footnav.pipeline.navigation.eskf``).
    With the update's larger noise in the gate (before), the bias estimate still held 0.24 °/s of it 4 s later."""
    from footnav.pipeline.navigation.navigator import Navigator
    from footnav.pipeline.samples import ImuBatch

    t, acc, gyr = _still(10_000, 0.0, 0.0, np.zeros(3))
    turn = slice(3000, 6000)
    gyr[turn, 2] += np.radians(0.8)
    nav = Navigator(NavConfig(), RATE_HZ)
    n = t.size
    out = nav.process(ImuBatch(t, acc, gyr, np.arange(n), np.zeros(n, dtype=np.int64)))
    assert out is not None and out.stance[100:].all()
    state = nav.state
    assert state is not None
    assert abs(np.degrees(state[15])) < 0.05
    heading_change_deg = np.degrees(yaw_of(out.quat_nb_wxyz[-1]) - yaw_of(out.quat_nb_wxyz[2000]))
    assert heading_change_deg == pytest.approx(2.4, abs=0.15)


def test_nan_samples_are_flagged_not_fatal() -> None:
    t, acc, gyr = _still(5000, 0.0, 0.0, np.zeros(3))
    acc[3000:3010] = np.nan
    out, stats = navigate(t, acc, gyr, RATE_HZ)
    assert out is not None and stats.bad_samples == 10
    assert np.isfinite(out.pos_n_m).all()
    assert np.abs(out.pos_n_m[-1]).max() < 1e-3


def test_impossible_samples_are_flagged_not_integrated() -> None:
    """A corrupt record (e.g. a flipped exponent bit: 1e30 m/s²) is a bad sample, not a number to integrate."""
    t, acc, gyr = _still(5000, 0.0, 0.0, np.zeros(3))
    acc[3000, 1] = 3.0e30
    gyr[3500, 2] = -7.0e12
    out, stats = navigate(t, acc, gyr, RATE_HZ)
    assert out is not None and stats.bad_samples == 2
    assert np.isfinite(out.pos_n_m).all()
    assert np.abs(out.pos_n_m[-1]).max() < 1e-3


def test_duplicate_and_gapped_timestamps_are_counted() -> None:
    t, acc, gyr = _still(5000, 0.0, 0.0, np.zeros(3))
    t[2000] = t[1999]  # duplicate
    t[4000:] += 0.2  # a 200 ms gap
    out, stats = navigate(t, acc, gyr, RATE_HZ)
    assert out is not None
    assert stats.bad_dt == 1 and stats.gaps == 1
    assert np.isfinite(out.pos_n_m).all()


def test_no_still_period_means_no_estimates() -> None:
    rng = np.random.default_rng(0)
    n = 3000
    acc = np.array([0, 0, 9.8]) + rng.normal(0, 4.0, (n, 3))
    gyr = rng.normal(0, 2.0, (n, 3))
    out, stats = navigate(np.arange(n) / RATE_HZ, acc, gyr, RATE_HZ)
    assert out is None
    assert stats.aligned_at_s is None and stats.samples_out == 0


def test_strapdown_step_is_second_order_on_exact_signals() -> None:
    """The filter's step with no updates integrates the emulator's noise-free signals from the true
    initial state with a global error ∝ dt²: four times the rate, at least eight times less error
    (16 in theory; footnav.pipeline.navigation.eskf docstring)."""
    from footnav.device.emulator.motion.gait import simulate_walk

    errors = []
    for rate_hz in (250.0, 1000.0):
        truth = simulate_walk("figure8", 8.0, rate_hz=rate_hz, seed=0)
        n = len(truth)
        x = np.zeros(16)
        x[0:3], x[3:6], x[6:10] = truth.pos_n_m[0], truth.vel_n_mps[0], truth.quat_nb_wxyz[0]
        par = eskf.FilterParams(*[0.0] * len(eskf.FilterParams._fields))._replace(g=9.80665, dt_max=1.0)
        dt = np.full(n, 1.0 / rate_hz)
        dt[0] = 0.0  # sample 0 is the initial state
        pos, vel, quat, cov = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4, 4))
        eskf.run_filter(
            x, np.eye(eskf.N_STATE), truth.acc_b_mps2, truth.gyr_b_radps, NO_CLIPPED_RATES, dt, np.zeros(n, np.bool_),
            np.zeros(n),
            par, pos, vel, quat, cov, np.zeros(eskf.N_CNT, np.int64),
        )  # fmt: skip
        errors.append(float(np.linalg.norm(pos[-1] - truth.pos_n_m[-1])))
    coarse, fine = errors
    assert fine < coarse / 8.0 and fine < 2e-3


def _moving_filter(speed_mps: float):  # type: ignore[no-untyped-def]
    """A filter aligned on a still unit that the nominal state says moves at ``speed_mps`` along x,
    its velocity known to 1 cm/s: one still sample follows."""
    from footnav.pipeline.navigation.navigator import filter_parameters, initial_error_sigmas
    from footnav.pipeline.navigation.profiles import get_profile

    prof = get_profile("mpu6500x4")
    _, acc, gyr = _still(1, 0.0, 0.0, np.zeros(3))
    x = np.zeros(16)
    x[3], x[6] = speed_mps, 1.0
    P = np.diag(initial_error_sigmas(NavConfig(profile=prof), prof) ** 2)
    P[3:6, 3:6] = np.eye(3) * 0.01**2
    par = filter_parameters(prof, RATE_HZ, 9.80665, 0.05)
    return x, P, acc, gyr, par


@pytest.mark.parametrize(("ratio", "applied"), [(0.9, False), (np.nan, False), (0.5, True), (0.1, True)])
def test_zero_velocity_sample_of_a_moving_foot(ratio: float, applied: bool) -> None:
    """A stance sample the detector is unsure of (T/γ above 0.5, or from another source) while the filter
    knows the foot moves at 1.9 m/s (the PyShoe mid-swing "stance" of ``footnav.pipeline.navigation.eskf``) is
    skipped and
    counted; one the detector is sure of is applied however far the filter's velocity is from zero."""
    x, P, acc, gyr, par = _moving_filter(1.9)
    counters, state = np.zeros(eskf.N_CNT, dtype=np.int64), eskf.new_filter_state()
    out = np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 4)), np.empty((1, 4, 4))
    eskf.run_filter(
        x, P, acc, gyr, NO_CLIPPED_RATES, np.array([1e-3]), np.array([True]), np.array([ratio]), par, *out, counters,
        state,
    )  # fmt: skip
    assert counters[eskf.CNT_ZUPT_REJECTED] == (0 if applied else 1)
    assert counters[eskf.CNT_UPDATES] == (1 if applied else 0)
    assert state[eskf.STATE_LAST_REJECTED] == (0 if applied else 1)
    # applied: with the velocity's σ equal to the update's noise, one update halves it
    assert (x[3] < 0.6 * 1.9) if applied else (x[3] == pytest.approx(1.9, abs=1e-3))


def test_zero_velocity_sample_near_rest_is_applied_when_unsure() -> None:
    """At the end of a swing the velocity error is centimetres per second: an unsure sample's NIS is far
    below the gate (10σ), so it is applied."""
    x, P, acc, gyr, par = _moving_filter(0.05)
    counters = np.zeros(eskf.N_CNT, dtype=np.int64)
    out = np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 4)), np.empty((1, 4, 4))
    eskf.run_filter(
        x, P, acc, gyr, NO_CLIPPED_RATES, np.array([1e-3]), np.array([True]), np.array([0.99]), par, *out, counters
    )
    assert counters[eskf.CNT_ZUPT_REJECTED] == 0 and counters[eskf.CNT_UPDATES] == 1


def _standing_run(par: eskf.FilterParams, first_still_s: float, pause_s: float, stand_s: float, turn_radps: np.ndarray):
    """A level unit, still throughout: a still start (the first stance), a pause the detector calls
    motion, then a long stance in which the gyroscope reads ``turn_radps`` (3,) more than its bias.
    Returns the gyroscope bias estimate after each sample, (n, 3), and the filter's carried state."""
    n1, n2, n3 = (round(s * RATE_HZ) for s in (first_still_s, pause_s, stand_s))
    n = n1 + n2 + n3
    _, acc, gyr = _still(n, 0.0, 0.0, np.zeros(3), seed=3)
    gyr[n1 + n2 :] += turn_radps
    stance = np.ones(n, dtype=np.bool_)
    stance[n1 : n1 + n2] = False
    from footnav.pipeline.navigation.navigator import initial_error_sigmas
    from footnav.pipeline.navigation.profiles import get_profile

    prof = get_profile("mpu6500x4")
    x = np.zeros(16)
    x[6] = 1.0
    P = np.diag(initial_error_sigmas(NavConfig(profile=prof), prof) ** 2)
    counters, state = np.zeros(eskf.N_CNT, dtype=np.int64), eskf.new_filter_state()
    bias = np.empty((n, 3))
    out = np.empty((1, 3)), np.empty((1, 3)), np.empty((1, 4)), np.empty((1, 4, 4))
    for k in range(n):  # one sample per call: the filter state carries the stance between calls, as live
        eskf.run_filter(
            x, P, acc[k : k + 1], gyr[k : k + 1], NO_CLIPPED_RATES, np.array([1.0 / RATE_HZ]), stance[k : k + 1],
            np.zeros(1), par, *out, counters, state,
        )  # fmt: skip
        bias[k] = x[13:16]
    return bias, state, (n1, n2, n3)


def test_a_standing_foot_may_turn_about_the_vertical() -> None:
    """After 2 s of a stance that is not the first, the zero-rate update admits a turn about the
    vertical (``footnav.pipeline.navigation.eskf``): a slow 0.3 °/s turn read there moves the vertical bias estimate far
    less than a full-strength update would, while the same reading about a horizontal axis (which the
    floor holds) is learnt as before; the still start and a stance's first 2 s are untouched."""
    from footnav.pipeline.navigation.navigator import STANDING_AFTER_S, filter_parameters
    from footnav.pipeline.navigation.profiles import get_profile

    par = filter_parameters(get_profile("mpu6500x4"), RATE_HZ, 9.80665, 0.05)
    plain = par._replace(standing_turn=0.0)
    turn = np.radians([0.3, 0.0, 0.3])  # about body x (horizontal, level unit) and z (vertical)
    standing, state, (n1, n2, n3) = _standing_run(par, 3.0, 0.5, 8.0, turn)
    full, _, _ = _standing_run(plain, 3.0, 0.5, 8.0, turn)
    assert state[eskf.STATE_STARTED] == 1 and state[eskf.STATE_STANCE_RUN] == n3
    np.testing.assert_array_equal(standing[: n1 + n2], full[: n1 + n2])  # the still start is not touched
    after = n1 + n2 + round(STANDING_AFTER_S * RATE_HZ)
    np.testing.assert_array_equal(standing[:after], full[:after])  # nor the first 2 s of a stance
    moved_standing = standing[-1] - standing[after - 1]
    moved_full = full[-1] - full[after - 1]
    # horizontal: the same learning either way (the full update learns 44 % of the turn in these 6 s);
    # vertical: 12 % of what the full update learns (measured 2026-12-02)
    assert moved_full[0] > 0.3 * turn[0] and moved_standing[0] == pytest.approx(moved_full[0], rel=0.05)
    assert moved_full[2] > 0.3 * turn[2] and abs(moved_standing[2]) < 0.2 * moved_full[2]
