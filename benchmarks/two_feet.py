"""Two feet coupled by the inter-foot distance bound against two independent feet, on emulated walks.

    .venv/bin/python -m benchmarks.two_feet [--seeds 4] [--duration 90] [--bounds 2.1,1.6]

Each course (rectangle, figure-eight, line, stairs) and seed is walked by two emulated feet
(``two_feet_walks``), each given its own errors of the MPU-6500 x4 grade (biases, bias instability,
noise), without and with the axis errors ``gyro-bias-calibrated`` (the datasheet's gyroscope scale and
cross-axis errors, which make the heading drift). Both feet are navigated independently and coupled
(``footnav.pipeline.two_feet``) with each bound R of ``--bounds``. Printed per walk: each foot's final
and mean-along-the-walk horizontal error, independent and coupled (the first R), and the change of
the two feet's mean error in %; then per R the mean over the walks, how many got worse by more
than 1 cm, and the runtime ratio coupled / independent.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from footnav.device.emulator.motion.gait import GaitTruth, two_feet_walks
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.two_feet import FootSeparation, FootSignals, navigate_feet

COURSES = ("rectangle", "figure8", "line", "stairs")
WORSE_M = 0.01
"""A walk counts as worse when its mean horizontal error grew by more than this, m."""


def horizontal_errors(nav: NavBatch | None, truth: GaitTruth) -> tuple[float, float]:
    """(final, mean along the walk) horizontal error of one foot, m."""
    if nav is None:
        return float("nan"), float("nan")
    first = len(truth) - len(nav)
    e = np.hypot(*(nav.pos_n_m[:, :2] - truth.pos_n_m[first:, :2]).T)
    return float(e[-1]), float(e.mean())


def walk_signals(
    course: str, seed: int, duration_s: float, axes: str
) -> tuple[tuple[GaitTruth, GaitTruth], list[FootSignals]]:
    """The two feet's truth and their corrupted signals (seeds ``seed`` and ``seed + 1``)."""
    feet = two_feet_walks(course, duration_s, seed=seed)
    signals = []
    for i, tr in enumerate(feet):
        acc, gyr, _ = corrupt(
            tr.acc_b_mps2, tr.gyr_b_radps, tr.rate_hz, IMU_GRADES["mpu6500x4"], seed=seed + i, axes=axes
        )
        signals.append(FootSignals(tr.t_s, acc, gyr, tr.rate_hz))
    return feet, signals


Row = tuple[float, float, float, float, float, int]
"""(final L, final R, mean L, mean R, runtime s, corrections)."""


def run(course: str, seed: int, duration_s: float, axes: str, bounds: list[float]) -> dict[str, Row]:
    """Errors (final L, final R, mean L, mean R) and runtimes of one walk, independent and per bound."""
    (left, right), (sl, sr) = walk_signals(course, seed, duration_s, axes)
    out: dict[str, Row] = {}
    for name, coupling in [("ind", None), *[(f"{b:g}", FootSeparation(max_m=b)) for b in bounds]]:
        t0 = time.perf_counter()
        res = navigate_feet(sl, sr, coupling=coupling)
        dt = time.perf_counter() - t0
        (fl, ml), (fr, mr) = horizontal_errors(res.left, left), horizontal_errors(res.right, right)
        out[name] = (fl, fr, ml, mr, dt, len(res.corrections))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--duration", type=float, default=90.0)
    ap.add_argument("--bounds", default="2.1,1.6", help="R values, m, comma-separated (the first is tabled)")
    args = ap.parse_args(argv)
    bounds = [float(b) for b in args.bounds.split(",")]
    warm = walk_signals("line", 1, 10.0, "none")[1]
    navigate_feet(warm[0], warm[1], coupling=FootSeparation())  # compile first
    main_r = f"{bounds[0]:g}"
    print(f"two feet, {args.duration:.0f} s walks, mpu6500x4; horizontal error, m (L/R); coupled at R = {main_r} m")
    hdr = f"{'axes':<6}{'course':<10}{'seed':>4}  {'indep end':>11} {'indep mean':>11}  "
    print(hdr + f"{'coupled end':>11} {'cpl mean':>11} {'updates':>7} {'change':>7}")
    summary: dict[tuple[str, str], list[tuple[float, float, float, float]]] = {}
    for axes in ("none", "gyro-bias-calibrated"):
        tag = "none" if axes == "none" else "axes"
        for course in COURSES:
            for seed in range(1, args.seeds + 1):
                r = run(course, seed, args.duration, axes, bounds)
                fl, fr, ml, mr, ti, _ = r["ind"]
                ind_mean = 0.5 * (ml + mr)
                for b in bounds:
                    cfl, cfr, cml, cmr, tc, nc = r[f"{b:g}"]
                    cpl_mean = 0.5 * (cml + cmr)
                    summary.setdefault((tag, f"{b:g}"), []).append((ind_mean, cpl_mean, ti, tc))
                    if f"{b:g}" == main_r:
                        change = 100.0 * (cpl_mean / ind_mean - 1.0)
                        print(
                            f"{tag:<6}{course:<10}{seed:>4}  {fl:>5.2f}/{fr:<5.2f} {ml:>5.2f}/{mr:<5.2f}  "
                            f"{cfl:>5.2f}/{cfr:<5.2f} {cml:>5.2f}/{cmr:<5.2f} {nc:>7} {change:>+6.0f}%"
                        )
    print()
    print(
        f"{'axes':<6}{'R m':>5}  {'indep mean':>10} {'coupled':>8} {'change':>7} {'worse>1cm':>10} {'time ratio':>10}"
    )
    for (tag, bound), rows in summary.items():
        a = np.array(rows)
        worse = int(np.count_nonzero(a[:, 1] - a[:, 0] > WORSE_M))
        change = 100.0 * (a[:, 1].mean() / a[:, 0].mean() - 1.0)
        print(
            f"{tag:<6}{bound:>5}  {a[:, 0].mean():>10.3f} {a[:, 1].mean():>8.3f} {change:>+6.0f}% "
            f"{worse:>6}/{len(a):<3} {a[:, 3].sum() / a[:, 2].sum():>10.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
