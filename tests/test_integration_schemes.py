"""The integration-scheme experiment (``benchmarks.integration_schemes``): its scheme 0 is the filter's
own step, and every candidate integrates the emulator's exact signals to second order."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.integration_schemes import (
    CONING,
    END_SAMPLE,
    INCREMENTS,
    MIDPOINT,
    NAMES,
    RK4,
    TRAPEZOID,
    pure_strapdown,
    run_filter_scheme,
)
from device.emulator.gait import simulate_walk
from device.emulator.imu_errors import corrupt
from pipeline import eskf
from pipeline.navigator import NavConfig, filter_parameters, initial_error_sigmas
from pipeline.profiles import get_profile
from pipeline.quaternion import quat_from_rotvec, quat_mul


def _outputs(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    return np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4, 4))


@pytest.mark.parametrize("scheme", range(len(NAMES)))
def test_first_order_scheme_is_the_filter_and_others_run_every_branch(scheme: int) -> None:
    truth = simulate_walk("rectangle", 12.0, rate_hz=400.0, seed=0)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=3)
    acc, gyr = acc.copy(), gyr.copy()
    acc[2000], gyr[2500] = np.nan, np.nan  # bad samples
    dt = np.full(len(truth), 1.0 / truth.rate_hz)
    dt[3000], dt[3500] = 0.0, 0.5  # a duplicated stamp and a gap
    prof = get_profile("mpu6500x4")
    par = filter_parameters(prof, truth.rate_hz, 9.80665, 0.1)
    x0 = np.zeros(16)
    x0[6] = 1.0
    P0 = np.diag(initial_error_sigmas(NavConfig(profile=prof), prof) ** 2)
    n = len(truth)
    # the detector's T/γ, beyond [0, 1] and NaN too (the filter clamps it)
    ratio = np.random.default_rng(0).uniform(-0.1, 1.2, n)
    ratio[100] = np.nan
    runs = []
    for fn in (eskf.run_filter, run_filter_scheme):
        x, P = x0.copy(), P0.copy()
        out = _outputs(n)
        counters = np.zeros(eskf.N_CNT, dtype=np.int64)
        args = (x, P, acc, gyr, dt, truth.stance, ratio, par, *out, counters)
        if fn is run_filter_scheme:
            fn(*args, scheme)
        else:
            fn(*args)
        runs.append((x, P, out, counters))
    (x_a, P_a, out_a, c_a), (x_b, P_b, out_b, c_b) = runs
    np.testing.assert_array_equal(c_a, c_b)
    assert np.all(np.isfinite(out_b[0]))
    if scheme == END_SAMPLE:
        np.testing.assert_array_equal(x_a, x_b)
        np.testing.assert_array_equal(P_a, P_b)
        for a, b in zip(out_a, out_b, strict=True):
            np.testing.assert_array_equal(a, b)
    else:
        assert not np.array_equal(x_a, x_b)


@pytest.mark.parametrize("scheme", [END_SAMPLE, TRAPEZOID, CONING, INCREMENTS, MIDPOINT, RK4])
def test_every_scheme_is_second_order_on_the_emulator_signals(scheme: int) -> None:
    """Global error ∝ dt²: four times the rate, at least eight times less error (16 in theory)."""
    coarse = pure_strapdown(scheme, "figure8", 8.0, 250.0)
    fine = pure_strapdown(scheme, "figure8", 8.0, 1000.0)
    assert fine[0] < coarse[0] / 8.0 and fine[2] < coarse[2] / 8.0
    assert fine[0] < 2e-3


def test_coning_term_is_the_second_order_rotation_vector() -> None:
    """One interval of a rate ω(t) = a + (b − a) t/dt turning its axis: with the coning term the
    attitude matches a fine integration to O(dt³), without it only to O(dt²)."""
    a, b, h = np.array([4.0, 0.0, 1.0]), np.array([0.0, 5.0, -1.0]), 0.01
    q_ref = np.array([1.0, 0.0, 0.0, 0.0])
    m = 20000
    for i in range(m):
        tau = (i + 0.5) / m
        q_ref = quat_mul(q_ref, quat_from_rotvec((a + (b - a) * tau) * h / m))
    errors = {}
    for scheme in (TRAPEZOID, CONING):
        x = np.zeros(16)
        x[6] = 1.0
        par = np.zeros(eskf.N_PAR)
        par[eskf.PAR_G], par[eskf.PAR_DT_MAX] = 9.8, 1.0
        acc = np.tile([0.0, 0.0, 9.8], (2, 1))
        gyr = np.stack([a, b])
        out = _outputs(2)
        run_filter_scheme(
            x, np.eye(15), acc, gyr, np.array([0.0, h]), np.zeros(2, np.bool_), np.zeros(2), par, *out,
            np.zeros(eskf.N_CNT, np.int64), scheme,
        )  # fmt: skip
        errors[scheme] = 2.0 * np.arccos(min(1.0, abs(float(out[2][1] @ q_ref))))
    assert errors[CONING] < errors[TRAPEZOID] / 20.0
