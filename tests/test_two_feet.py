"""Two feet coupled by the inter-foot distance bound (``footnav.pipeline.two_feet``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from footnav.device.emulator.motion.gait import GaitTruth, two_feet_walks
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.pipeline.navigation.navigator import NavConfig, Navigator, navigate
from footnav.pipeline.two_feet import FootSeparation, FootSignals, apply_separation, navigate_feet
from footnav.pipeline.two_feet.heading import YAW_INDEX, RelativeHeading, heading_rad, wrap_rad
from footnav.pipeline.two_feet.separation import LEFT_ORIGIN_M, RIGHT_ORIGIN_M, horizontal_separation


def _signals(course: str, seed: int, duration_s: float, axes: str) -> tuple[list[GaitTruth], list[FootSignals]]:
    feet = list(two_feet_walks(course, duration_s, seed=seed))
    out = []
    for i, tr in enumerate(feet):
        acc, gyr, _ = corrupt(
            tr.acc_b_mps2, tr.gyr_b_radps, tr.rate_hz, IMU_GRADES["mpu6500x4"], seed=seed + i, axes=axes
        )
        out.append(FootSignals(tr.t_s, acc, gyr, tr.rate_hz))
    return feet, out


def _mean_error(nav: object, truth: GaitTruth) -> float:
    pos = nav.pos_n_m  # type: ignore[attr-defined]
    first = len(truth) - len(pos)
    return float(np.hypot(*(pos[:, :2] - truth.pos_n_m[first:, :2]).T).mean())


def test_independent_feet_are_the_one_foot_navigation_bit_for_bit() -> None:
    _, (sl, sr) = _signals("rectangle", 3, 30.0, "gyro-bias-calibrated")
    res = navigate_feet(sl, sr, coupling=None)
    for sig, est in ((sl, res.left), (sr, res.right)):
        alone, _ = navigate(sig.t_s, sig.acc_b_mps2, sig.gyr_b_radps, sig.rate_hz)
        assert alone is not None and est is not None
        np.testing.assert_array_equal(est.pos_n_m, alone.pos_n_m)
        np.testing.assert_array_equal(est.quat_nb_wxyz, alone.quat_nb_wxyz)
    assert res.corrections == []


def test_a_bound_never_reached_changes_nothing() -> None:
    _, (sl, sr) = _signals("figure8", 2, 40.0, "gyro-bias-calibrated")
    ind = navigate_feet(sl, sr, coupling=None)
    far = navigate_feet(sl, sr, coupling=FootSeparation(max_m=50.0, heading=None))
    assert far.corrections == []
    assert ind.left is not None and far.left is not None and ind.right is not None and far.right is not None
    np.testing.assert_array_equal(far.left.pos_n_m, ind.left.pos_n_m)
    np.testing.assert_array_equal(far.right.pos_n_m, ind.right.pos_n_m)


def test_a_violated_bound_is_applied_and_the_distance_ends_within_it() -> None:
    # the left foot's gyroscope reads 4 % too much about z: its heading runs away on the turns
    _, (sl, sr) = _signals("figure8", 1, 40.0, "none")
    gyr = sl.gyr_b_radps.copy()
    gyr[:, 2] *= 1.04
    sl = FootSignals(sl.t_s, sl.acc_b_mps2, gyr, sl.rate_hz)
    bound = FootSeparation(max_m=1.6)  # above the walk's true largest distance (1.52 m)
    nav_l, nav_r = Navigator(NavConfig(), sl.rate_hz), Navigator(NavConfig(), sr.rate_hz)
    applied = []
    step = 50
    for a in range(0, len(sl.t_s), step):
        nav_l.process(sl.batch().select(slice(a, a + step)))
        nav_r.process(sr.batch().select(slice(a, a + step)))
        d_before = apply_separation(nav_l, nav_r, bound)
        if np.isfinite(d_before):
            delta = horizontal_separation(nav_l, nav_r, bound)
            assert delta is not None
            applied.append((d_before, float(np.hypot(delta[0], delta[1]))))
    assert len(applied) > 5
    before, after = np.array(applied).T
    assert np.all(before > bound.max_m)
    assert np.all(after <= bound.max_m + 0.01)


def test_coupled_beats_independent_with_axis_errors() -> None:
    # a walk with the datasheet axis errors on which the feet's headings drift apart (benchmarks.two_feet)
    feet, (sl, sr) = _signals("figure8", 2, 90.0, "gyro-bias-calibrated")
    ind = navigate_feet(sl, sr, coupling=None)
    e_ind = _mean_error(ind.left, feet[0]) + _mean_error(ind.right, feet[1])
    bound = navigate_feet(sl, sr, coupling=FootSeparation(heading=None))  # the distance bound alone
    assert bound.corrections and not bound.heading_updates
    e_bound = _mean_error(bound.left, feet[0]) + _mean_error(bound.right, feet[1])
    assert e_bound < 0.9 * e_ind
    cpl = navigate_feet(sl, sr, coupling=FootSeparation(heading=RelativeHeading()))  # bound and relative heading
    assert len(cpl.heading_updates) > 100
    e_cpl = _mean_error(cpl.left, feet[0]) + _mean_error(cpl.right, feet[1])
    assert e_cpl < 0.6 * e_ind and e_cpl < 0.8 * e_bound


@pytest.mark.parametrize("course", ["rectangle", "figure8", "line", "stairs"])
def test_the_truth_never_violates_the_coupling(course: str) -> None:
    # error-free signals: the estimates are the truth to within the integration, so every innovation of
    # the relative heading is the model's own error on the course, and the distance bound never acts. 90 s:
    # on the stairs the emulated feet's landings drift together (0.03 s apart from 65 s on, seed 3), and
    # the feet then settle in one batch; paired in the order they settled, one foot was measured against
    # the other's newer stance (innovations of 45°)
    left, right = two_feet_walks(course, 90.0, seed=3)
    n = min(len(left), len(right))
    delta = left.pos_n_m[:n, :2] + LEFT_ORIGIN_M[:2] - right.pos_n_m[:n, :2] - RIGHT_ORIGIN_M[:2]
    assert np.hypot(*delta.T).max() < FootSeparation().max_m - 0.15  # 0.78 m level, 1.02 m stairs
    sig = [FootSignals(tr.t_s, tr.acc_b_mps2, tr.gyr_b_radps, tr.rate_hz) for tr in (left, right)]
    # the default band holds the model's error: no update at all
    assert navigate_feet(sig[0], sig[1], coupling=FootSeparation()).heading_updates == []
    res = navigate_feet(sig[0], sig[1], coupling=FootSeparation(heading=RelativeHeading(band_rad=0.0)))
    assert res.corrections == []
    assert len(res.heading_updates) > 100  # about one per stance of each foot (135-161 in 90 s)
    # within 1σ of each (σ_ψ, widened by the turn mismatch m where a turn starts or ends; m bounds the
    # midpoint model's error), and on straight walking well within σ_ψ
    y, sigma = np.abs(res.heading_innovation_rad), np.array(res.heading_sigma_rad)
    assert np.all(y < sigma)
    straight = sigma < 1.001 * RelativeHeading().sigma_rad
    assert straight.sum() > 30 and y[straight].max() < 0.1 * RelativeHeading().sigma_rad


def test_heading_alone_acts_without_the_bound() -> None:
    feet, (sl, sr) = _signals("rectangle", 2, 60.0, "gyro-bias-calibrated")
    ind = navigate_feet(sl, sr, coupling=None)
    head = navigate_feet(sl, sr, coupling=FootSeparation(max_m=math.inf, heading=RelativeHeading()))
    assert head.corrections == [] and head.heading_updates
    e_ind = _mean_error(ind.left, feet[0]) + _mean_error(ind.right, feet[1])
    e_head = _mean_error(head.left, feet[0]) + _mean_error(head.right, feet[1])
    assert e_head < 0.7 * e_ind


def test_update_error_state_turns_the_heading_by_the_gain() -> None:
    nav = Navigator(NavConfig(), 1000.0)
    h = np.zeros(15)
    h[YAW_INDEX] = 1.0
    nav.update_error_state(h, 0.1, 0.01)
    nav.add_error_variance(YAW_INDEX, 1.0)
    assert nav.state is None and nav.error_cov is None  # before alignment: no-ops
    _, (sl, _) = _signals("line", 1, 5.0, "none")
    nav.process(sl.batch())
    x0, cov0 = nav.state, nav.error_cov
    assert x0 is not None and cov0 is not None
    nav.add_error_variance(YAW_INDEX, 1e-4)
    cov1 = nav.error_cov
    assert cov1 is not None
    assert cov1[YAW_INDEX, YAW_INDEX] == pytest.approx(cov0[YAW_INDEX, YAW_INDEX] + 1e-4, rel=1e-12)
    nav.update_error_state(h, 0.02, float(cov1[YAW_INDEX, YAW_INDEX]))  # noise = prior: half the way
    x1, cov2 = nav.state, nav.error_cov
    assert x1 is not None and cov2 is not None
    assert wrap_rad(heading_rad(x1[6:10]) - heading_rad(x0[6:10])) == pytest.approx(0.01, rel=1e-2)
    assert cov2[YAW_INDEX, YAW_INDEX] == pytest.approx(0.5 * cov1[YAW_INDEX, YAW_INDEX], rel=1e-3)


def test_update_position_before_alignment_is_a_no_op() -> None:
    nav = Navigator(NavConfig(), 1000.0)
    nav.update_position(np.array([1.0, 0.0, 0.0]), 1.0, 0.01)
    assert nav.state is None and nav.position_cov is None


@pytest.mark.parametrize("shift_m", [0.5, -0.3])
def test_update_position_moves_the_position_by_the_gain(shift_m: float) -> None:
    _, (sl, _) = _signals("line", 1, 5.0, "none")
    nav = Navigator(NavConfig(), sl.rate_hz)
    nav.process(sl.batch())
    x0, cov = nav.state, nav.position_cov
    assert x0 is not None and cov is not None
    nav.update_position(np.array([1.0, 0.0, 0.0]), shift_m, float(cov[0, 0]))  # noise = prior: half the way
    x1 = nav.state
    assert x1 is not None
    assert x1[0] - x0[0] == pytest.approx(0.5 * shift_m, rel=1e-9)
