"""Filter consistency on emulated walks: Monte Carlo NEES against its χ² band.

    .venv/bin/python -m benchmarks.consistency [--runs 16] [--duration 240]

For each walk (rectangle, figure-eight) the same true motion is measured by ``--runs`` emulated
IMUs with independent errors (``footnav.device.emulator.sensors.imu_errors``, MPU-6500 grade, seeds 1..M) and
navigated. At every second t the average NEES over the runs,

    ANEES(t) = (1/M) Σ_m e_m(t)ᵀ P_m(t)⁻¹ e_m(t),

is compared with the two-sided 95 % band of a consistent filter, [χ²_{dM}(0.025), χ²_{dM}(0.975)] / M
for d position components (Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking
and Navigation", Wiley 2001, §5.4.2, eqs. 5.4.2-3 to -6). Printed: the median ANEES (a consistent
filter gives d) and the share of seconds inside, below (covariance too large) and above (too small)
the band, for the 3D position, the horizontal pair and the height.

Three models are run on the same records:

- ``default``: the unit profile footnav navigates with (``footnav.pipeline.navigation.profiles``), which adds process
  noise for what real units have and the emulator does not (scale factor, cross-axis, vibration,
  a standing foot's residual rotation);
- ``emulated``: a profile holding exactly the emulator's error model
  (:func:`profile_of_grade`): its white-noise densities (one-sided, so σ² per sample is density² ·
  rate / 2), turn-on biases, and the Gauss-Markov drift as a bias random walk of the same driving
  density; no signal-proportional, vibration or residual-rotation terms. The zero-velocity update's
  own model (the foot rolling about heel and toe, the soft vertical update) is kept: the emulated
  gait has both.
- ``true st.``: that profile without the update's stance terms (:func:`with_true_stances`), the
  filter run on the walk's true stances instead of the detector's (:func:`navigate_true_stances`):
  the filter where its whole model holds but the drift (a Gauss-Markov process taken as a random
  walk, which overstates it at 240 s). What separates it from ``emulated`` is the stance detection.

The samples of one walk are strongly correlated in time, so the share inside the band is a
description, not a test at 95 %.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import numpy as np
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.device.emulator.sensors.imu_errors import AXIS_ERRORS, IMU_GRADES, ImuGrade, corrupt
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation.alignment import align_from_still
from footnav.pipeline.navigation.batches import NO_CLIPPED_RATES
from footnav.pipeline.navigation.navigator import NavConfig, filter_start, navigate
from footnav.pipeline.navigation.profiles import UnitProfile, get_profile
from scipy.stats import chi2

F64 = np.ndarray
WALKS = ("rectangle", "figure8")
RATE_HZ = 1000.0
GRADE = "mpu6500x4"
COMPONENTS = (("3D", slice(0, 3)), ("xy", slice(0, 2)), ("z", slice(2, 3)))
TRUE_STANCE_ZUPT_SIGMA_MPS = 1e-3
"""The zero-velocity noise where the IMU is exactly still: small, not zero, for the update's
numerics."""


def profile_of_grade(grade: ImuGrade, base: UnitProfile) -> UnitProfile:
    """``base`` with the sensor terms replaced by the emulator's error model of ``grade``.

    White noise: the emulator's one-sided density d gives σ² = d² · rate / 2 per sample, the profile's
    density is used as σ² = density² · rate (``footnav.pipeline.navigation.navigator.filter_parameters``), so d / √2.
    Drift: a first-order Gauss-Markov bias of stationary σ_bi and correlation time τ is driven by
    σ_bi √(2/τ) per √s, taken as the random walk density (exact for t ≪ τ). Turn-on bias: its σ,
    with the drift's stationary σ added in quadrature (the drift starts from its stationary law).
    """
    return dataclasses.replace(
        base,
        name=f"{base.name} (emulated errors)",
        acc_noise_mps2_rthz=grade.acc_noise_density_mps2_rthz / math.sqrt(2.0),
        gyr_noise_radps_rthz=grade.gyr_noise_density_radps_rthz / math.sqrt(2.0),
        acc_bias_rw_mps3_rthz=grade.acc_bias_instability_mps2 * math.sqrt(2.0 / grade.bias_correlation_time_s),
        gyr_bias_rw_radps2_rthz=grade.gyr_bias_instability_radps * math.sqrt(2.0 / grade.bias_correlation_time_s),
        acc_bias_init_mps2=math.hypot(grade.acc_bias_sigma_mps2, grade.acc_bias_instability_mps2),
        gyr_bias_init_radps=math.hypot(grade.gyr_bias_sigma_radps, grade.gyr_bias_instability_radps),
        motion_acc_mps2=0.0,
        motion_gyr_radps=0.0,
        acc_scale_error=0.0,
        gyr_scale_error=0.0,
        zaru_sigma_radps=0.0,
    )


def with_true_stances(profile: UnitProfile) -> UnitProfile:
    """``profile`` with the zero-velocity update's model of a detected stance removed (no roll about
    heel or toe, no soft vertical component, 1 mm/s of noise): the model of the emulator's true
    stances, in which the IMU is exactly still."""
    return dataclasses.replace(
        profile,
        name=f"{profile.name} (true stances)",
        roll_lever_m=0.0,
        zupt_vertical_sigma_mps=0.0,
        zupt_sigma_mps=TRUE_STANCE_ZUPT_SIGMA_MPS,
    )


def navigate_true_stances(truth: GaitTruth, acc_b_mps2: F64, gyr_b_radps: F64, profile: UnitProfile) -> tuple[F64, F64]:
    """The filter alone over emulated samples with the walk's true stances instead of a detector,
    aligned on the first ``NavConfig.align_s`` of the (still) start as the navigator would be.

    Returns: (n, 3) positions and (n, 3, 3) position covariances of the samples after alignment.
    """
    cfg = NavConfig(profile=profile)
    start = max(2, round(cfg.align_s * RATE_HZ))
    x, P, par = filter_start(cfg, RATE_HZ, align_from_still(acc_b_mps2[:start], gyr_b_radps[:start]))
    n = truth.t_s.shape[0] - start
    pos, vel, quat, cov = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4, 4))
    eskf.run_filter(
        x, P, acc_b_mps2[start:], gyr_b_radps[start:], NO_CLIPPED_RATES,
        eskf.sample_intervals(truth.t_s[start:], truth.t_s[start - 1], cfg.dt_max_s),
        np.ascontiguousarray(truth.stance[start:]), np.zeros(n), par, pos, vel, quat, cov,
        np.zeros(eskf.N_CNT, dtype=np.int64),
    )  # fmt: skip
    return pos, cov[:, :3, :3]


def nees_per_second(
    path: str,
    duration_s: float,
    runs: int,
    profile: UnitProfile,
    axes: str = "none",
    *,
    true_stances: bool = False,
    grade: ImuGrade | str = GRADE,
) -> dict[str, F64]:
    """(runs, seconds) NEES of each component (``COMPONENTS``), from 1 s after alignment, with the
    emulated IMU's scale-factor and cross-axis errors ``axes`` (``footnav.device.emulator.sensors.imu_errors``), through
    the navigator (its detector's stances) or, with ``true_stances``, the filter on the walk's own."""
    truth = simulate_walk(path, duration_s, rate_hz=RATE_HZ, seed=0)
    out: dict[str, list[F64]] = {name: [] for name, _ in COMPONENTS}
    for seed in range(1, runs + 1):
        acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, RATE_HZ, grade, seed=seed, axes=axes)
        if true_stances:
            pos, pos_cov = navigate_true_stances(truth, acc, gyr, profile)
        else:
            nav, _ = navigate(truth.t_s, acc, gyr, RATE_HZ, NavConfig(profile=profile))
            assert nav is not None
            pos, pos_cov = nav.pos_n_m, nav.pos_cov_n_m2
        every = int(RATE_HZ)
        err = (pos - truth.pos_n_m[-len(pos) :])[every::every]
        cov = pos_cov[every::every]
        for name, sl in COMPONENTS:
            e, c = err[:, sl], cov[:, sl, sl]
            out[name].append(np.einsum("ni,nij,nj->n", e, np.linalg.inv(c), e))
    return {name: np.array(v) for name, v in out.items()}


def summary(nees: F64, dof: int) -> tuple[float, float, float, float]:
    """(median ANEES, share inside, below, above the 95 % band) of (runs, times) NEES values."""
    runs = nees.shape[0]
    anees = nees.mean(axis=0)
    lo, hi = chi2.ppf([0.025, 0.975], dof * runs) / runs
    return (
        float(np.median(anees)),
        float(np.mean((anees >= lo) & (anees <= hi))),
        float(np.mean(anees < lo)),
        float(np.mean(anees > hi)),
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=16)
    ap.add_argument("--duration", type=float, default=240.0, help="s per walk")
    ap.add_argument("--axis-errors", choices=sorted(AXIS_ERRORS), default="none", help="of the emulated IMUs")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    base = get_profile(GRADE)
    emulated = profile_of_grade(IMU_GRADES[GRADE], base)
    profiles = (
        ("default", base, False),
        ("emulated", emulated, False),
        ("true st.", with_true_stances(emulated), True),
    )
    print(
        f"{args.runs} runs per walk, {args.duration:.0f} s, axis errors {args.axis_errors!r}, "
        "ANEES per second against its 95 % band"
    )
    print(
        f"{'walk':<10} {'profile':<9} "
        + "  ".join(f"{name + ' (d=' + str(sl.stop - sl.start) + ')':>27}" for name, sl in COMPONENTS)
    )
    print(f"{'':<20} " + "  ".join(f"{'median  in/below/above %':>27}" for _ in COMPONENTS))
    for path in WALKS:
        for label, profile, true_stances in profiles:
            nees = nees_per_second(path, args.duration, args.runs, profile, args.axis_errors, true_stances=true_stances)
            cells = []
            for name, sl in COMPONENTS:
                med, inside, below, above = summary(nees[name], sl.stop - sl.start)
                cells.append(f"{med:6.2f}  {100 * inside:4.0f}/{100 * below:3.0f}/{100 * above:3.0f}")
            print(f"{path:<10} {label:<9} " + "  ".join(f"{c:>27}" for c in cells))
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
