"""Where one axis error loses height: per stride, in swing and in stance, on an emulated level walk.

    .venv/bin/python -m benchmarks.axis_errors [--path rectangle] [--duration 60] [--size 0.01]

The emulated walk's error-free signals are given one error at a time (a gyroscope or accelerometer
scale factor or cross-axis sensitivity of ``--size``, ``footnav.device.emulator.sensors.imu_errors``, body axes x
forward, y left, z up) and navigated with the default configuration. Printed per error: the final
height error and the median height change of the error over a swing (stance end to stance start,
the emulator's true stance) and over a stance. The real loops' signature (README "Accuracy": the
OpenShoe loop loses 1.6 cm per stride, all in swing, with no velocity error left at its end) is what
an error that zero-velocity updates cannot observe leaves: here it is to be compared with the
signature each axis error leaves. Nothing is asserted.
"""

from __future__ import annotations

import argparse

import numpy as np
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.pipeline.navigation.navigator import NavConfig, navigate
from footnav.pipeline.navigation.profiles import get_profile

F64 = np.ndarray


def height_signature(walk: GaitTruth, m_acc: F64, m_gyr: F64) -> tuple[float, float, float]:
    """(final height error, median change of the height error per swing, per stance), m, of the walk's
    error-free signals through the axis-error matrices ``m_acc``, ``m_gyr`` (3, 3)."""
    acc = walk.acc_b_mps2 @ m_acc.T
    gyr = walk.gyr_b_radps @ m_gyr.T
    nav, _ = navigate(walk.t_s, acc, gyr, walk.rate_hz, NavConfig(profile=get_profile("mpu6500x4")))
    if nav is None:
        raise RuntimeError("the navigator never aligned")
    first = len(walk) - len(nav)
    stance = walk.stance[first:].astype(np.int8)
    err_z = nav.pos_n_m[:, 2] - walk.pos_n_m[first:, 2]
    lift = np.flatnonzero(np.diff(stance) == -1)  # last stance sample before a swing
    land = np.flatnonzero(np.diff(stance) == 1)  # last swing sample before a stance
    swing = [err_z[land[land > k][0]] - err_z[k] for k in lift if np.any(land > k)]
    still = [err_z[lift[lift > k][0]] - err_z[k] for k in land if np.any(lift > k)]
    return float(err_z[-1]), float(np.median(swing)), float(np.median(still))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--path", default="rectangle")
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--size", type=float, default=0.01, help="each error, as a fraction (default 1 %%)")
    args = ap.parse_args(argv)
    walk = simulate_walk(args.path, args.duration, rate_hz=1000.0, seed=1)
    eye = np.eye(3)
    cases: list[tuple[str, F64, F64]] = [("none", eye, eye)]
    for sensor in ("gyro", "acc"):
        for i in range(3):
            for j in range(3):
                m = eye.copy()
                m[i, j] += args.size
                what = f"scale {'xyz'[i]}" if i == j else f"cross {'xyz'[i]}<-{'xyz'[j]}"
                cases.append((f"{sensor} {what}", eye if sensor == "gyro" else m, m if sensor == "gyro" else eye))
    print(f"{args.path}, {args.duration:.0f} s, error-free signals, one error of {100 * args.size:g} % at a time")
    print(f"{'error':<20}{'z end cm':>10}{'swing mm':>10}{'stance mm':>11}   (median per stride)")
    for name, m_acc, m_gyr in cases:
        z_end, swing, stance = height_signature(walk, m_acc, m_gyr)
        print(f"{name:<20}{100 * z_end:>+10.2f}{1000 * swing:>+10.2f}{1000 * stance:>+11.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
