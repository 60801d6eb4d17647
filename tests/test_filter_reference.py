"""The compiled filter (``footnav.pipeline.navigation.eskf``) against the plain numpy reference in ``benchmarks/``.

The reference multiplies full (15, 15) matrices and writes the Joseph form with ``np.linalg``; the
compiled filter uses block-sparse propagation, rank-3 updates and one-triangle symmetry. On a walk
with a bad sample, a duplicated timestamp, a gap and samples marked clipped in it they must agree to
rounding.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation.alignment import align_from_still
from footnav.pipeline.navigation.batches import zupt_ratio
from footnav.pipeline.navigation.navigator import filter_parameters
from footnav.pipeline.navigation.profiles import get_profile
from footnav.pipeline.navigation.saturation import clipped_rate_variance
from footnav.pipeline.stance.detectors import DetectorParams, StreamingDetector

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # benchmarks/ is not an installed package
    sys.path.insert(0, str(ROOT))

from benchmarks.numpy_filter import run_filter_numpy  # noqa: E402

RATE_HZ = 1000.0


def _inputs() -> tuple[np.ndarray, ...]:
    truth = simulate_walk("rectangle", 6.0, RATE_HZ, seed=4, initial_still_s=1.0)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, RATE_HZ, "mpu6500x4", seed=5)
    t = truth.t_s.copy()
    acc[2500, 1] = np.nan  # a bad sample mid-walk
    t[3000] = t[2999]  # a duplicated timestamp
    t[4000:] += 0.08  # a gap
    stat, threshold, stance = StreamingDetector(DetectorParams(), RATE_HZ).update(acc, gyr)
    ratio = zupt_ratio(stat, threshold)
    ratio[np.flatnonzero(stance)[::50]] = np.nan  # a NaN T/γ at some stance samples (taken as 1)
    al = align_from_still(acc[:500], gyr[:500])
    x = np.zeros(16)
    x[6:10] = al.quat_nb_wxyz
    P = np.diag(np.array([1e-5] * 3 + [0.01] * 3 + [0.01, 0.01, 2e-4] + [0.05] * 3 + [2e-3] * 3) ** 2)
    par = filter_parameters(get_profile("mpu6500x4"), RATE_HZ, al.gravity_mps2, 0.05)
    dt = np.diff(t, prepend=t[0] - 1.0 / RATE_HZ)
    # the fastest tenth of the pitch rates taken as clipped (uncertain along their own axis)
    clipped = np.zeros(acc.shape, dtype=bool)
    clipped[:, 1] = np.abs(gyr[:, 1]) > np.quantile(np.abs(gyr[:, 1]), 0.9)
    var = clipped_rate_variance(gyr, clipped)
    return x, P, acc, gyr, var, dt, stance, ratio, par


def test_compiled_filter_matches_numpy_reference() -> None:
    x, P, acc, gyr, var, dt, stance, ratio, par = _inputs()
    n = acc.shape[0]
    ref = run_filter_numpy(x, P, acc, gyr, dt, stance, ratio, par, var)
    x_c, P_c = x.copy(), P.copy()
    pos, vel, quat, pos_cov = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4, 4))
    counters, state = np.zeros(eskf.N_CNT, dtype=np.int64), eskf.new_filter_state()
    eskf.run_filter(x_c, P_c, acc, gyr, var, dt, stance, ratio, par, pos, vel, quat, pos_cov, counters, state)

    np.testing.assert_array_equal(counters, ref.counters)
    np.testing.assert_array_equal(state, ref.filter_state)
    assert counters[eskf.CNT_BAD_SAMPLE] == 1 and counters[eskf.CNT_BAD_DT] == 1 and counters[eskf.CNT_GAP] == 1
    assert counters[eskf.CNT_UPDATES] > 1000 and counters[eskf.CNT_ZARU] > 100 and counters[eskf.CNT_ZARU_REJECTED] > 0
    assert np.ptp(pos[:, 0]) > 3.0  # it walked
    np.testing.assert_allclose(pos, ref.pos_n_m, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(vel, ref.vel_n_mps, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(quat, ref.quat_nb_wxyz, rtol=0, atol=1e-9)
    np.testing.assert_allclose(pos_cov, ref.pos_cov_n_m2, rtol=1e-7, atol=1e-15)
    np.testing.assert_allclose(P_c, ref.P, rtol=1e-7, atol=1e-15)
    np.testing.assert_array_equal(P_c, P_c.T)  # symmetric by construction


def test_batches_do_not_change_the_result() -> None:
    x, P, acc, gyr, var, dt, stance, ratio, par = _inputs()
    n = acc.shape[0]

    def run(cuts: list[int]) -> np.ndarray:
        x_c, P_c = x.copy(), P.copy()
        pos = np.empty((n, 3))
        counters, state = np.zeros(eskf.N_CNT, dtype=np.int64), eskf.new_filter_state()
        for a, b in zip([0, *cuts], [*cuts, n], strict=True):
            m = b - a
            eskf.run_filter(
                x_c, P_c, acc[a:b], gyr[a:b], var[a:b], dt[a:b], stance[a:b], ratio[a:b], par,
                pos[a:b], np.empty((m, 3)), np.empty((m, 4)), np.empty((m, 4, 4)), counters, state,
            )  # fmt: skip
        return pos

    np.testing.assert_array_equal(run([]), run([1, 2, 777, 2500, 2501, 5999]))
