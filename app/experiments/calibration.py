"""Field calibration on the emulated miscalibrated unit: recovered parameters, then a walk with and without.

1. The unit (:class:`footnav.device.emulator.sensors.icosahedron.Miscalibration`: known K, L, b, K_T, b_T, gyro biases
   and slopes; white noise and in-run drift of ``--grade``) warms up while it turns through the 20
   icosahedron faces; :class:`footnav.pipeline.calibration.procedure.FaceCollector` finds the still faces and
   fits. The table gives each parameter with its 1σ, the truth, the error and the issue's tolerance.
2. The same unit walks ``--path`` (``footnav.device.emulator.motion.gait.simulate_walk``) while it warms further; the
   navigator (``footnav.pipeline.navigation.navigator.navigate``) runs on the raw samples, on the samples corrected with
   the calibration and their temperature, and corrected without temperature (the model at its
   reference temperature: what ``live`` does on the 0x40 stream). Position errors against the truth,
   side by side. The navigator runs on zero-velocity aiding alone (its stance height constraint,
   ``footnav.pipeline.stance.levels``, off), so the table shows what the calibration does to the inertial
   solution itself; with the constraint the level walk's height stays on the floor either way.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

import numpy as np
from footnav.app.commands.calibrate import parameter_table
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.icosahedron import (
    Miscalibration,
    miscalibrated_signals,
    simulate_icosahedron,
    warm_up_c,
)
from footnav.pipeline.calibration.model import ImuCalibration
from footnav.pipeline.calibration.procedure import FaceCollector
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.navigation.navigator import NavConfig, navigate
from numpy.typing import NDArray

F64 = NDArray[np.float64]
RATE_HZ = 1000.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--path", default="rectangle", help="walk course (default rectangle)")
    parser.add_argument("--duration", type=float, default=60.0, metavar="S", help="walk length, s (default 60)")
    parser.add_argument("--grade", default="mpu6500x4", help="noise grade of the emulated unit")
    parser.add_argument("--seed", type=int, default=3, help="seed of the sensor noise")


def calibrate_emulated(errors: Miscalibration, *, grade: str, seed: int) -> tuple[ImuCalibration, tuple[float, float]]:
    """Run the procedure on the emulated unit (samples fed in 50 ms reads): the fit and the temperature range.

    Raises
    ------
    CalibrationError
        the faces did not determine the calibration.
    """
    truth = simulate_icosahedron(RATE_HZ)
    temp = warm_up_c(truth.t_s)
    acc, gyr = miscalibrated_signals(
        truth.acc_b_mps2, truth.gyr_b_radps, temp, RATE_HZ, errors=errors, grade=grade, seed=seed
    )
    collector = FaceCollector(RATE_HZ)
    for a in range(0, len(truth), 50):
        collector.feed(truth.t_s[a : a + 50], acc[a : a + 50], gyr[a : a + 50], temp[a : a + 50])
    return collector.finish(), (float(temp.min()), float(temp.max()))


@dataclass(frozen=True, slots=True)
class WalkErrors:
    """Position errors of one navigation run against the truth, m."""

    label: str
    final_m: float
    final_vertical_m: float
    mean_m: float
    mean_vertical_m: float
    max_vertical_m: float


def walk_errors(label: str, t_s: F64, acc: F64, gyr: F64, pos_true: F64) -> WalkErrors:
    """Navigate (n,) samples and compare with the true positions (n, 3)."""
    nav, _ = navigate(t_s, acc, gyr, RATE_HZ, NavConfig(stance_levels=False))
    if nav is None:
        raise FootnavError(f"{label}: the navigator produced no output (no still period to align on)")
    idx = np.rint(nav.t_s * RATE_HZ).astype(np.int64)
    err = nav.pos_n_m - pos_true[idx]
    norm = np.linalg.norm(err, axis=1)
    vert = np.abs(err[:, 2])
    return WalkErrors(
        label, float(norm[-1]), float(vert[-1]), float(norm.mean()), float(vert.mean()), float(vert.max())
    )


def compare_walk(
    cal: ImuCalibration, errors: Miscalibration, *, path: str, duration_s: float, grade: str, seed: int
) -> tuple[list[WalkErrors], float, tuple[float, float]]:
    """The walk navigated raw, calibrated with temperature, calibrated at the reference temperature.

    Returns the rows, the distance walked (m) and the walk's temperature range (°C).
    """
    walk = simulate_walk(path, duration_s, rate_hz=RATE_HZ, seed=seed)
    temp = warm_up_c(walk.t_s, start_c=32.0, end_c=42.0, time_constant_s=120.0)
    acc, gyr = miscalibrated_signals(
        walk.acc_b_mps2, walk.gyr_b_radps, temp, RATE_HZ, errors=errors, grade=grade, seed=seed + 100
    )
    acc_c, gyr_c = cal.correct_arrays(acc, gyr, temp)
    acc_r, gyr_r = cal.correct_arrays(acc, gyr, None)
    rows = [
        walk_errors("no calibration", walk.t_s, acc, gyr, walk.pos_n_m),
        walk_errors("calibrated (with temperature)", walk.t_s, acc_c, gyr_c, walk.pos_n_m),
        walk_errors("calibrated at t_ref (no temperature)", walk.t_s, acc_r, gyr_r, walk.pos_n_m),
    ]
    clean_acc, clean_gyr = miscalibrated_signals(
        walk.acc_b_mps2, walk.gyr_b_radps, temp, RATE_HZ, errors=_no_errors(), grade=grade, seed=seed + 100
    )
    rows.append(walk_errors("perfectly calibrated (same noise)", walk.t_s, clean_acc, clean_gyr, walk.pos_n_m))
    return rows, walk.distance_m, (float(temp.min()), float(temp.max()))


def _no_errors() -> Miscalibration:
    """A unit with no deterministic errors (scale 1, no misalignment, biases or temperature terms)."""
    theta = np.zeros(15)
    theta[0:3] = 1.0
    return Miscalibration(theta=theta, gyr_bias_radps=np.zeros(3), gyr_bias_slope_radps_per_c=np.zeros(3))


def run(args: argparse.Namespace) -> int:
    errors = Miscalibration()
    cal, (c0, c1) = calibrate_emulated(errors, grade=args.grade, seed=args.seed)
    print(
        f"calibration of the emulated unit ({args.grade}, icosahedron, 20 faces offered, "
        f"warming {c0:.1f} → {c1:.1f} °C)"
    )
    for line in parameter_table(cal, errors):
        print(line)
    rows, distance, (t0, t1) = compare_walk(
        cal, errors, path=args.path, duration_s=args.duration, grade=args.grade, seed=args.seed
    )
    print()
    print(f"walk: {args.path}, {args.duration:g} s, {distance:.1f} m, unit warming {t0:.1f} → {t1:.1f} °C")
    print(f"{'navigation':<38}{'final m':>9}{'final |z| m':>12}{'mean m':>9}{'mean |z| m':>11}{'max |z| m':>10}")
    for r in rows:
        print(
            f"{r.label:<38}{r.final_m:>9.3f}{r.final_vertical_m:>12.3f}{r.mean_m:>9.3f}"
            f"{r.mean_vertical_m:>11.3f}{r.max_vertical_m:>10.3f}"
        )
    print("(final error as % of distance: " + ", ".join(f"{100 * r.final_m / distance:.2f}" for r in rows) + ")")
    return 0 if all(math.isfinite(r.final_m) for r in rows) else 1
