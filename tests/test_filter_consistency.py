"""The filter's covariance against its actual error: Monte Carlo NEES on emulated walks.

Where the filter's model holds (the emulator's white noise and turn-on biases, the profile holding
exactly those, the walk's true stances), the average NEES over independent runs must sit in the
95 % χ² band of a consistent filter (Bar-Shalom, Li, Kirubarajan 2001, §5.4.2); the same check with
the gyroscope noise misstated must fail, both ways. The navigator as users run it (its detector, the
unit's default profile) must never claim less error than it makes. ``benchmarks.consistency`` prints
the full table (240 s walks, in-run drift, detected stances with the matched profile).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES
from footnav.pipeline.navigation.profiles import UnitProfile, get_profile

from benchmarks.consistency import GRADE, nees_per_second, profile_of_grade, summary, with_true_stances

RUNS = 12
DURATION_S = 60.0
# white noise and turn-on biases only: the drift is a Gauss-Markov process, which the profiles'
# bias random walk matches only for times well under its correlation time
WHITE_AND_TURN_ON = dataclasses.replace(
    IMU_GRADES[GRADE], acc_bias_instability_mps2=0.0, gyr_bias_instability_radps=0.0
)
MATCHED = with_true_stances(profile_of_grade(WHITE_AND_TURN_ON, get_profile(GRADE)))
DOF = {"3D": 3, "xy": 2, "z": 1}


def _summaries(path: str, profile: UnitProfile, *, true_stances: bool) -> dict[str, tuple[float, float, float, float]]:
    nees = nees_per_second(path, DURATION_S, RUNS, profile, true_stances=true_stances, grade=WHITE_AND_TURN_ON)
    assert all(np.isfinite(v).all() and v.shape[0] == RUNS for v in nees.values())
    return {name: summary(nees[name], dof) for name, dof in DOF.items()}


@pytest.mark.parametrize("path", ["rectangle", "figure8"])
def test_matched_filter_is_consistent(path: str) -> None:
    for name, (median, inside, _, _) in _summaries(path, MATCHED, true_stances=True).items():
        dof = DOF[name]
        # measured 2026-12-02: median 3D ANEES 2.84 / 2.61, 81-83 % of the seconds inside
        assert 0.6 * dof <= median <= 1.4 * dof, (name, median)
        assert inside >= 0.6, (name, inside)


@pytest.mark.parametrize(("factor", "side"), [(1 / 3, "above"), (3.0, "below")])
def test_misstated_gyroscope_noise_fails_the_check(factor: float, side: str) -> None:
    wrong = dataclasses.replace(MATCHED, gyr_noise_radps_rthz=MATCHED.gyr_noise_radps_rthz * factor)
    _, inside, below, above = _summaries("figure8", wrong, true_stances=True)["3D"]
    assert inside < 0.1
    assert (above if side == "above" else below) > 0.8


def test_navigator_never_understates_its_error() -> None:
    """With its detector and the unit's default profile: conservative, never above the band."""
    for name, (median, _, _, above) in _summaries("rectangle", get_profile(GRADE), true_stances=False).items():
        assert above == 0.0, (name, above)
        assert median < DOF[name], (name, median)
