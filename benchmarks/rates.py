"""Accuracy by sample rate: emulated walks streamed at lower rates, each navigated at its own rate.

    .venv/bin/python -m benchmarks.rates [--seeds 3] [--duration 60]

Each row is a walk of the emulator (MPU-6500-class errors) at a unit's base rate (1000, 819.2 or
250 Hz), every k-th sample kept as a rate divider keeps it, navigated by ``navigate`` at the
resulting rate, as a live session does once the unit's clock has given it: end error as a percentage
of the distance walked, per seed and their median.
"""

from __future__ import annotations

import argparse

import numpy as np
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.pipeline.navigation.navigator import NavConfig, navigate
from footnav.pipeline.navigation.profiles import get_profile

STREAMS = ((1000.0, 1), (819.2, 1), (250.0, 1), (1000.0, 8), (250.0, 4), (250.0, 8))
"""(base rate, Hz; every k-th sample): 1000, 819.2, 250, 125, 62.5 and 31.25 Hz."""


def end_error_pct(path: str, base_hz: float, every: int, seed: int, duration_s: float) -> float:
    """End error of one walk, % of the distance walked."""
    truth = simulate_walk(path, duration_s, rate_hz=base_hz, seed=seed)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, base_hz, IMU_GRADES["mpu6500x4"], seed=seed + 10)
    t, a, g = truth.t_s[::every], acc[::every], gyr[::every]
    nav, _ = navigate(t, a, g, base_hz / every, NavConfig(profile=get_profile("mpu6500x4")))
    if nav is None:
        return float("nan")
    k = round(float(nav.t_s[-1]) * base_hz)
    return 100.0 * float(np.linalg.norm(nav.pos_n_m[-1] - truth.pos_n_m[k])) / truth.distance_m


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.rates", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="walks per row (default 3)")
    ap.add_argument("--duration", type=float, default=60.0, metavar="S", help="walk length, s (default 60)")
    args = ap.parse_args(argv)
    print(f"  {'walk':10} {'rate':>9}  end error, % of distance (seeds 1..{args.seeds}; median)")
    for path in ("rectangle", "stairs"):
        for base_hz, every in STREAMS:
            errors = [end_error_pct(path, base_hz, every, s, args.duration) for s in range(1, args.seeds + 1)]
            cells = " ".join(f"{e:6.3f}" for e in errors)
            print(f"  {path:10} {base_hz / every:7.2f} Hz  {cells}   median {np.median(errors):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
