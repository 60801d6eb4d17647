"""SHOE detector: the vectorised statistic equals Skog et al.'s formula, streaming equals batch."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.detectors import ShoeParams, StreamingShoe, shoe_statistic


def _shoe_by_definition(acc: np.ndarray, gyr: np.ndarray, w: int, p: ShoeParams) -> np.ndarray:
    """Skog et al. 2010 eq. 11, written as a plain loop over windows."""
    out = []
    for end in range(w, acc.shape[0] + 1):
        a, g = acc[end - w : end], gyr[end - w : end]
        mean = a.mean(axis=0)
        up = p.gravity_mps2 * mean / np.linalg.norm(mean)
        t = ((a - up) ** 2).sum(axis=1) / p.sigma_acc_mps2**2 + (g**2).sum(axis=1) / p.sigma_gyr_radps**2
        out.append(t.mean())
    return np.array(out)


def _walkish(n: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    acc = np.array([0.0, 0.0, 9.80665]) + rng.normal(0, 0.05, (n, 3))
    gyr = rng.normal(0, 0.003, (n, 3))
    moving = (np.arange(n) // 300) % 2 == 1
    acc[moving] += rng.normal(0, 5.0, (moving.sum(), 3))
    gyr[moving] += rng.normal(0, 3.0, (moving.sum(), 3))
    return acc, gyr


def test_statistic_matches_definition() -> None:
    acc, gyr = _walkish(1200)
    p = ShoeParams()
    np.testing.assert_allclose(
        shoe_statistic(acc, gyr, 7, p), _shoe_by_definition(acc, gyr, 7, p), rtol=1e-7, atol=1e-6
    )


@pytest.mark.parametrize("chunk", [1, 7, 64, 5000])
def test_streaming_is_independent_of_batching(chunk: int) -> None:
    acc, gyr = _walkish(3000)
    whole_stat, whole_still = StreamingShoe(ShoeParams(), 1000.0).update(acc, gyr)
    det = StreamingShoe(ShoeParams(), 1000.0)
    parts = [det.update(acc[i : i + chunk], gyr[i : i + chunk]) for i in range(0, 3000, chunk)]
    np.testing.assert_allclose(np.concatenate([s for s, _ in parts]), whole_stat, rtol=1e-7, atol=1e-9)
    np.testing.assert_array_equal(np.concatenate([z for _, z in parts]), whole_still)


def test_separates_rest_from_motion() -> None:
    acc, gyr = _walkish(3000)
    _, still = StreamingShoe(ShoeParams(), 1000.0).update(acc, gyr)
    moving = (np.arange(3000) // 300) % 2 == 1
    interior = np.ones(3000, bool)
    for edge in range(0, 3000, 300):  # windows straddling a transition may go either way
        interior[max(0, edge - 10) : edge + 10] = False
    assert still[~moving & interior].all()
    assert not still[moving & interior].any()


def test_non_finite_samples_only_spoil_their_windows() -> None:
    acc, gyr = _walkish(900)
    acc[100] = np.nan
    det = StreamingShoe(ShoeParams(), 1000.0)
    stat, still = det.update(acc, gyr)
    w = det.window
    assert np.isinf(stat[100 : 100 + w]).all() and not still[100 : 100 + w].any()
    assert still[100 + w : 290].all()  # the rest of the still period is unaffected
