"""Zero-velocity detection with ToF height (footnav.pipeline.stance.height_detector): unit behaviour and, on an
emulated walk, its stance flags against the truth alone and combined with the inertial detector."""

from __future__ import annotations

import numpy as np
import pytest
from footnav.app.experiments import tof as exp
from footnav.pipeline.aiding.tof_types import DEFAULT_DIR_B, DEFAULT_LEVER_B_M, TofConfig
from footnav.pipeline.navigation.navigator import navigate
from footnav.pipeline.stance.height_detector import HeightDetectorParams, HeightStanceDetector


def _detector(mode: str = "height") -> HeightStanceDetector:
    return HeightStanceDetector(
        HeightDetectorParams(mode=mode),  # type: ignore[arg-type]
        np.asarray(DEFAULT_LEVER_B_M),
        np.asarray(DEFAULT_DIR_B),
        1000.0,
    )


def test_height_is_the_median_of_fresh_readings() -> None:
    det = _detector()
    rest = np.array([0.03 / np.cos(np.radians(9.65)), 0.03, 0.04 / np.cos(np.radians(9.65))])
    # toe over a step edge reads 16 cm more; the median of the three still says "down"
    det.add(
        np.array([0.010, 0.011, 0.012]), np.array([0, 1, 2]), rest + np.array([0.16, 0.0, 0.001]), np.zeros(3, np.uint8)
    )
    h = det.height_m(np.array([0.012, 0.05, 0.07]))
    assert h[0] == pytest.approx(0.001, abs=2e-3)
    assert h[1] == pytest.approx(0.0, abs=2e-3)  # the toe reading is stale by now: median of two
    assert np.isnan(h[2])  # nothing fresh: height unknown, never "down"
    # invalid statuses and NaN ranges are not heights
    det.add(np.array([0.08]), np.array([1]), np.array([0.03]), np.array([1], np.uint8))
    assert np.isnan(det.height_m(np.array([0.081]))[0])


def test_still_and_lifted_foot() -> None:
    det = _detector()
    n = 100
    t = np.arange(n) / 1000.0
    acc, gyr = np.tile([0.0, 0.0, 9.81], (n, 1)), np.zeros((n, 3))
    det.add(t[::10], np.arange(10) % 3, np.full(10, 0.03), np.zeros(10, np.uint8))
    assert det.update(t, acc, gyr, np.zeros(n, bool))[30:].all()
    lifted = _detector()
    lifted.add(t[::10], np.arange(10) % 3, np.full(10, 0.20), np.zeros(10, np.uint8))
    assert not lifted.update(t, acc, gyr, np.ones(n, bool)).any()  # held still in the air: not stance


@pytest.fixture(scope="module")
def walk70() -> exp.Recording:
    return exp.record("rectangle", 70.0, seed=1)


def test_modes_on_the_70s_walk(walk70: exp.Recording) -> None:
    t = walk70.truth
    result = {}
    for mode in ("inertial", "height", "and", "or"):
        cfg = TofConfig(detector=HeightDetectorParams(mode=mode))  # type: ignore[arg-type]
        nav, _ = navigate(t.t_s, walk70.acc_b_mps2, walk70.gyr_b_radps, t.rate_hz, ranges=walk70.ranges, tof=cfg)
        assert nav is not None
        truth_still = t.stance[len(t) - len(nav) :]
        precision = float(np.mean(truth_still[nav.stance]))
        recall = float(np.mean(nav.stance[truth_still]))
        result[mode] = (precision, recall, exp.figures(t, nav, {}))
    # measured (seed 1): inertial 0.904/0.947, height 0.891/0.999, and 0.955/0.947, or 0.849/0.999
    assert result["height"][1] > 0.99 and result["height"][0] > 0.85
    assert result["and"][0] > result["inertial"][0] + 0.03
    assert result["or"][1] > result["inertial"][1]
    # every mode keeps the clearance within 1 cm RMS on the walk
    assert all(f.clearance_rms_m < 0.01 for _, _, f in result.values())
