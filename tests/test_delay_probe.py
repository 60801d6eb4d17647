"""The accelerometer-gyroscope delay probe (``benchmarks.delay_probe``): with the delay fixed at 0 it
is the numpy reference filter, and on an emulated walk with an injected delay it recovers the delay
and removes the vertical error the delay causes."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from device.emulator.gait import simulate_walk
from device.emulator.imu_errors import corrupt
from pipeline.navigator import NavConfig, navigate
from pipeline.profiles import get_profile

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # benchmarks/ is not an installed package
    sys.path.insert(0, str(ROOT))

from benchmarks.delay_probe import TAU, delay_filter_in_navigator, run_filter_delay  # noqa: E402
from benchmarks.numpy_filter import run_filter_numpy  # noqa: E402
from tests.test_filter_reference import _inputs  # noqa: E402


def test_without_a_delay_it_is_the_reference_filter() -> None:
    x, P, acc, gyr, dt, stance, _, par = _inputs()
    n = 3000
    # T/γ = 0: the probe keeps the zero-velocity noise equal on all axes
    ref = run_filter_numpy(x, P, acc[:n], gyr[:n], dt[:n], stance[:n], np.zeros(n), par)
    run = run_filter_delay(x, P, acc[:n], gyr[:n], dt[:n], stance[:n], par, sigma_tau_s=0.0)
    np.testing.assert_array_equal(run.counters, ref.counters)
    np.testing.assert_allclose(run.pos_n_m, ref.pos_n_m, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.P[:TAU, :TAU], ref.P, rtol=1e-7, atol=1e-15)
    assert np.all(run.tau_s == 0.0)


def test_recovers_an_injected_delay_and_its_vertical_error() -> None:
    rate_hz = 500.0
    truth = simulate_walk("rectangle", 30.0, rate_hz=rate_hz, seed=0)
    delay_s = 0.005
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, rate_hz, "mpu6500x4", seed=7, gyr_delay_s=delay_s)
    cfg = NavConfig(profile=get_profile("mpu6500x4"))
    plain, _ = navigate(truth.t_s, acc, gyr, rate_hz, cfg)
    with delay_filter_in_navigator(sigma_tau_s=0.005) as runs:
        probed, _ = navigate(truth.t_s, acc, gyr, rate_hz, cfg)
    assert plain is not None and probed is not None
    tau = runs[-1].tau_s[-1]
    sd = float(np.sqrt(runs[-1].P[TAU, TAU]))
    assert abs(tau - delay_s) < max(3 * sd, 0.5e-3), (tau, sd)
    dz_plain = abs(plain.pos_n_m[-1, 2] - truth.pos_n_m[-1, 2])
    dz_probed = abs(probed.pos_n_m[-1, 2] - truth.pos_n_m[-1, 2])
    assert dz_plain > 0.1  # the delay alone costs the plain filter decimetres of height
    assert dz_probed < 0.3 * dz_plain, (dz_plain, dz_probed)
