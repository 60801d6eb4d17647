"""Zero-velocity detectors: statistics equal Skog et al.'s formulas; streaming equals batch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from footnav.pipeline.stance.detectors import DETECTOR_KINDS, DetectorKind, DetectorParams, StreamingDetector, statistic


def _by_definition(acc: np.ndarray, gyr: np.ndarray, w: int, p: DetectorParams) -> np.ndarray:
    """Skog et al. 2010, eqs. 11-14, written as a plain loop over windows."""
    out = []
    for end in range(w, acc.shape[0] + 1):
        a, g = acc[end - w : end], gyr[end - w : end]
        mean = a.mean(axis=0)
        if p.kind == "shoe":
            up = p.gravity_mps2 * mean / np.linalg.norm(mean)
            t = ((a - up) ** 2).sum(axis=1) / p.sigma_acc_mps2**2 + (g**2).sum(axis=1) / p.sigma_gyr_radps**2
        elif p.kind == "amv":
            t = ((a - mean) ** 2).sum(axis=1) / p.sigma_acc_mps2**2
        elif p.kind == "amag":
            t = (np.linalg.norm(a, axis=1) - p.gravity_mps2) ** 2 / p.sigma_acc_mps2**2
        else:
            t = (g**2).sum(axis=1) / p.sigma_gyr_radps**2
        out.append(t.mean())
    return np.array(out)


def _walkish(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Alternating 0.3 s rest and motion; returns acc, gyr and the moving mask."""
    rng = np.random.default_rng(seed)
    acc = np.array([0.0, 0.0, 9.80665]) + rng.normal(0, 0.05, (n, 3))
    gyr = rng.normal(0, 0.003, (n, 3))
    moving = (np.arange(n) // 300) % 2 == 1
    acc[moving] += rng.normal(0, 5.0, (moving.sum(), 3))
    gyr[moving] += rng.normal(0, 3.0, (moving.sum(), 3))
    return acc, gyr, moving


@pytest.mark.parametrize("kind", DETECTOR_KINDS)
def test_statistic_matches_definition(kind: DetectorKind) -> None:
    acc, gyr, _ = _walkish(1200)
    p = DetectorParams(kind=kind)
    np.testing.assert_allclose(statistic(acc, gyr, 7, p), _by_definition(acc, gyr, 7, p), rtol=1e-7, atol=1e-6)


@pytest.mark.parametrize("adaptive", [False, True])
@pytest.mark.parametrize("chunk", [1, 7, 64, 5000])
def test_streaming_is_independent_of_batching(chunk: int, adaptive: bool) -> None:
    acc, gyr, _ = _walkish(6000)
    p = DetectorParams(adaptive=adaptive)
    whole_stat, whole_th, whole_still = StreamingDetector(p, 1000.0).update(acc, gyr)
    det = StreamingDetector(p, 1000.0)
    parts = [det.update(acc[i : i + chunk], gyr[i : i + chunk]) for i in range(0, 6000, chunk)]
    np.testing.assert_allclose(np.concatenate([s for s, _, _ in parts]), whole_stat, rtol=1e-7, atol=1e-9)
    np.testing.assert_array_equal(np.concatenate([t for _, t, _ in parts]), whole_th)
    np.testing.assert_array_equal(np.concatenate([z for _, _, z in parts]), whole_still)


@pytest.mark.parametrize("adaptive", [False, True])
def test_separates_rest_from_motion(adaptive: bool) -> None:
    acc, gyr, moving = _walkish(6000)
    det = StreamingDetector(DetectorParams(adaptive=adaptive), 1000.0)
    _, _, still = det.update(acc, gyr)
    interior = np.ones(6000, bool)
    for edge in range(0, 6000, 300):  # windows straddling a transition may go either way,
        interior[max(0, edge - 10) : edge + 10 + det._min_run] = False  # and stance is debounced
    assert still[~moving & interior].all()
    assert not still[moving & interior].any()


def test_adaptive_threshold_follows_the_swing_level() -> None:
    """The same gait at a tenth of the motion energy must still be split into stance and swing."""
    acc, gyr, moving = _walkish(8000)
    g = np.array([0.0, 0.0, 9.80665])
    gentle_acc, gentle_gyr = g + (acc - g) * 0.05, gyr * 0.05  # ~2.6 decades less energy in swing
    base = DetectorParams()
    th_strong = StreamingDetector(base, 1000.0).update(acc, gyr)[1][-1]
    th_gentle = StreamingDetector(base, 1000.0).update(gentle_acc, gentle_gyr)[1][-1]
    assert th_gentle < th_strong / 10
    _, _, still = StreamingDetector(base, 1000.0).update(gentle_acc, gentle_gyr)
    late = np.arange(8000) > 2000
    settled = late & (np.arange(8000) % 300 >= 40)  # past the 20 ms debounce at each stance onset
    assert still[~moving & settled].mean() > 0.95 and still[moving & late].mean() < 0.05
    fixed = dataclasses.replace(base, adaptive=False, threshold=th_strong)
    _, _, still_fixed = StreamingDetector(fixed, 1000.0).update(gentle_acc, gentle_gyr)
    assert still_fixed[moving & late].mean() > 0.5  # a threshold fixed for the strong gait fails here


def test_non_finite_samples_only_spoil_their_windows() -> None:
    acc, gyr, _ = _walkish(900)
    acc[100] = np.nan
    det = StreamingDetector(DetectorParams(adaptive=False), 1000.0)
    stat, _, still = det.update(acc, gyr)
    w = det.window
    assert np.isinf(stat[100 : 100 + w]).all() and not still[100 : 100 + w].any()
    assert still[100 + w + det._min_run - 1 : 290].all()  # the rest of the still period is unaffected


@pytest.mark.parametrize("chunk", [1, 5, 33])
def test_debounce_drops_short_dips_and_is_batch_independent(chunk: int) -> None:
    rng = np.random.default_rng(5)
    n = 2000
    acc = np.array([0.0, 0.0, 9.80665]) + rng.normal(0, 5.0, (n, 3))
    gyr = rng.normal(0, 3.0, (n, 3))
    acc[500:512] = [0.0, 0.0, 9.80665]  # a 12 ms lull in a swing
    gyr[500:512] = 0.0
    acc[1000:1100] = [0.0, 0.0, 9.80665]  # a 100 ms stance
    gyr[1000:1100] = 0.0
    p = DetectorParams(adaptive=False)
    det = StreamingDetector(p, 1000.0)
    parts = [det.update(acc[i : i + chunk], gyr[i : i + chunk])[2] for i in range(0, n, chunk)]
    still = np.concatenate(parts)
    assert not still[480:540].any()
    assert still[1000 + det.window + det._min_run : 1100].all()
    np.testing.assert_array_equal(still, StreamingDetector(p, 1000.0).update(acc, gyr)[2])


@pytest.mark.parametrize("chunk", [1, 7, 400])
def test_a_stance_hovering_at_the_threshold_is_kept_and_a_swing_dip_is_not(chunk: int) -> None:
    """Hysteresis of the debounce: a running stance's statistic crosses the threshold every few
    samples but stays near it; a swing's ballistic dip comes from far above and stays rejected."""
    n = 400
    rng = np.random.default_rng(3)
    gyr = np.zeros((n, 3))
    acc = np.tile([0.0, 0.0, 9.80665], (n, 1))
    # swing: |ω| of 3 rad/s (T ~ 2e4 with the default scales, decades above the threshold of 25)
    gyr[:, 0] = 3.0
    gyr[100:112, 0] = 0.0  # a 12 ms ballistic dip of the swing
    # a 100 ms stance whose statistic wanders between 0.8 and 1.1 times the threshold:
    # T = mean |ω|² / σg² over the (two-sample) window, σg = 0.02 rad/s
    level = np.where(rng.random(100) < 0.5, 0.8, 1.1) * 25.0
    gyr[250:350, 0] = 0.02 * np.sqrt(level)
    p = DetectorParams(adaptive=False, window_s=0.002, min_stance_s=0.02)
    det = StreamingDetector(p, 1000.0)
    stat = np.empty(n)
    still = np.empty(n, dtype=bool)
    for i in range(0, n, chunk):
        stat[i : i + chunk], _, still[i : i + chunk] = det.update(acc[i : i + chunk], gyr[i : i + chunk])
    assert not still[90:130].any()
    below = stat < 25.0
    assert 0.2 < below[252:350].mean() < 0.8 and (stat[252:350] < 25.0 * 1.26).all()
    # after the first 20 ms (and the window) every sample below the threshold is stance, and only those
    np.testing.assert_array_equal(still[272:350], below[272:350])
    plain = StreamingDetector(dataclasses.replace(p, stance_hysteresis_decades=0.0), 1000.0)
    assert plain.update(acc, gyr)[2][250:350].sum() < still[250:350].sum() / 4  # without it: mostly lost
