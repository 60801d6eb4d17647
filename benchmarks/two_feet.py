"""Two feet coupled (distance bound, relative heading) against two independent feet, on emulated walks.

    .venv/bin/python -m benchmarks.two_feet [--seeds 4] [--first-seed 1] [--draws shared] [--duration 90]
        [--courses rectangle,...] [--axes none,gyro-bias-calibrated] [--bounds 1.2] [--variants default,...]
        [--heading-sigma 4] [--heading-drift 0] [--heading-drift-per-turn 0.02] [--heading-band 0]

Each course (rectangle, figure-eight, line, stairs; ``--courses`` a subset) and seed is walked by two
emulated feet (``two_feet_walks``), each given its own errors of the MPU-6500 x4 grade (biases, bias
instability, noise; error seeds as ``--draws`` says, ``DRAWS``), without and with the axis errors
``gyro-bias-calibrated`` (the datasheet's gyroscope scale and cross-axis errors, which make the heading
drift; ``--axes`` one of them). Both feet
are navigated independently and coupled (``footnav.pipeline.two_feet``) by each variant of
``--variants`` with each bound R of ``--bounds``: ``default`` the default ``FootSeparation`` with R (the
bound and the relative heading), ``distance`` the distance bound alone, ``heading`` the relative heading
constraint alone (σ, drift per stride and per turn from ``--heading-sigma``, ``--heading-drift`` in
degrees, ``--heading-drift-per-turn``, the band ``--heading-band`` in degrees), ``distance+heading``
both (those σ, drifts and band). Printed per walk: each foot's final and mean-along-the-walk horizontal
error, independent and coupled (the first variant and R), and the change of the two feet's mean error in
%; then per axis errors, course (and all courses) and variant the mean over the walks, its change, the
worst change of one walk, the noise (the SD over the seeds of the independent error: what changing the
IMU's error draw alone does), how many walks got worse by more than 1 cm, the runtime ratio coupled
/ independent, and the mean of the two feet's final error with its change. Beside the variants, the
ceiling of any relative constraint: the independent feet's error vectors averaged sample by sample
(``averaged_error``).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import numpy as np
from footnav.device.emulator.motion.gait import GaitTruth, two_feet_walks
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.two_feet import FootSeparation, FootSignals, TwoFeetResult, navigate_feet
from footnav.pipeline.two_feet.heading import RelativeHeading

COURSES = ("rectangle", "figure8", "line", "stairs")
AXES = ("none", "gyro-bias-calibrated")
"""The axis errors walked: none, and the datasheet's (``footnav.device.emulator.sensors.imu_errors``)."""
WORSE_M = 0.01
"""A walk counts as worse when its mean horizontal error grew by more than this, m."""


def error_track(nav: NavBatch, truth: GaitTruth) -> tuple[np.ndarray, np.ndarray]:
    """The sample numbers (n,) of one foot's estimates and their horizontal error vectors (n, 2), m."""
    first = len(truth) - len(nav)
    index = np.rint(truth.t_s[first:] * truth.rate_hz).astype(np.int64)
    return index, nav.pos_n_m[:, :2] - truth.pos_n_m[first:, :2]


def horizontal_errors(nav: NavBatch | None, truth: GaitTruth) -> tuple[float, float]:
    """(final, mean along the walk) horizontal error of one foot, m."""
    if nav is None:
        return float("nan"), float("nan")
    e = np.hypot(*error_track(nav, truth)[1].T)
    return float(e[-1]), float(e.mean())


def averaged_error(res: TwoFeetResult, left: GaitTruth, right: GaitTruth) -> tuple[float, float]:
    """(final, mean along the walk) of the independent feet's horizontal error vectors averaged at each
    common sample, m: what any coupling that knew exactly where each foot stands relative to the other
    could reach when the feet's errors are independent and alike (their common part is unobservable to
    it); the ceiling of a relative constraint."""
    if res.left is None or res.right is None:
        return float("nan"), float("nan")
    (il, el), (ir, er) = error_track(res.left, left), error_track(res.right, right)
    common, kl, kr = np.intersect1d(il, ir, assume_unique=True, return_indices=True)
    if not common.size:
        return float("nan"), float("nan")
    e = np.hypot(*(0.5 * (el[kl] + er[kr])).T)
    return float(e[-1]), float(e.mean())


DRAWS = ("shared", "own")
"""How each walk's feet draw their IMU errors: ``shared``, error seeds ``seed`` and ``seed + 1`` (the right foot
has the draw of the next seed's left foot: the tables of the design pages until 2026-12-08), or ``own``,
``2 seed`` and ``2 seed + 1`` (no draw in two walks of one course)."""


def walk_signals(
    course: str, seed: int, duration_s: float, axes: str, draws: str = "shared"
) -> tuple[tuple[GaitTruth, GaitTruth], list[FootSignals]]:
    """The two feet's truth (gait seed ``seed``) and their corrupted signals (error seeds as ``draws`` says)."""
    feet = two_feet_walks(course, duration_s, seed=seed)
    first = 2 * seed if draws == "own" else seed
    signals = []
    for i, tr in enumerate(feet):
        acc, gyr, _ = corrupt(
            tr.acc_b_mps2, tr.gyr_b_radps, tr.rate_hz, IMU_GRADES["mpu6500x4"], seed=first + i, axes=axes
        )
        signals.append(FootSignals(tr.t_s, acc, gyr, tr.rate_hz))
    return feet, signals


Row = tuple[float, float, float, float, float, int]
"""(final L, final R, mean L, mean R, runtime s, corrections)."""


VARIANTS = ("default", "distance", "heading", "distance+heading")
CEILING = "ceiling (errors averaged)"
"""The row of :func:`averaged_error`, printed beside the variants."""


def couplings(variants: list[str], bounds: list[float], heading: RelativeHeading) -> dict[str, FootSeparation]:
    """The couplings to compare, by name ``variant@R`` (``heading`` once, with no R)."""
    out: dict[str, FootSeparation] = {}
    for v in variants:
        if v not in VARIANTS:
            raise SystemExit(f"unknown variant {v!r}: one of {', '.join(VARIANTS)}")
        if v == "heading":
            out[v] = FootSeparation(max_m=math.inf, heading=heading)
            continue
        for b in bounds:
            base = FootSeparation(max_m=b)
            h = {"default": base.heading, "distance": None, "distance+heading": heading}[v]
            out[f"{v}@{b:g}"] = dataclasses.replace(base, heading=h)
    return out


def run(
    course: str, seed: int, duration_s: float, axes: str, variants: dict[str, FootSeparation], draws: str = "shared"
) -> dict[str, Row]:
    """Errors (final L, final R, mean L, mean R) and runtimes of one walk, independent and per variant."""
    (left, right), (sl, sr) = walk_signals(course, seed, duration_s, axes, draws)
    out: dict[str, Row] = {}
    for name, coupling in [("ind", None), *variants.items()]:
        t0 = time.perf_counter()
        res = navigate_feet(sl, sr, coupling=coupling)
        dt = time.perf_counter() - t0
        (fl, ml), (fr, mr) = horizontal_errors(res.left, left), horizontal_errors(res.right, right)
        out[name] = (fl, fr, ml, mr, dt, len(res.corrections) + len(res.heading_updates))
        if coupling is None:
            final, mean = averaged_error(res, left, right)
            out[CEILING] = (final, final, mean, mean, dt, 0)
    return out


Walk = tuple[float, float, float, float, float, float]
"""One walk in the summary: the two feet's mean error, independent and coupled; their runtimes; the two feet's
final error, independent and coupled (m, s)."""


def summarize(summary: dict[tuple[str, str, str], list[Walk]]) -> None:
    """Print, per axis errors, course (and all courses) and variant: the mean over the walks of the two
    feet's mean error, independent and coupled, its change, the worst change of one walk, the noise
    (the SD over the seeds of the independent error), the walks worse by more than ``WORSE_M``, the
    runtime ratio coupled / independent, and the mean of the two feet's final error and its change."""
    print(
        f"{'axes':<6}{'course':<10}{'variant@R m':>22}  {'indep mean':>10} {'coupled':>8} {'change':>7} "
        f"{'worst cm':>8} {'noise cm':>8} {'worse>1cm':>10} {'time ratio':>10}  {'indep end':>9} {'coupled':>8} "
        f"{'change':>7}"
    )
    for (tag, course, name), rows in summary.items():
        a = np.array(rows)
        worse = int(np.count_nonzero(a[:, 1] - a[:, 0] > WORSE_M))
        change = 100.0 * (a[:, 1].mean() / a[:, 0].mean() - 1.0)
        end_change = 100.0 * (a[:, 5].mean() / a[:, 4].mean() - 1.0)
        noise = 100.0 * float(np.std(a[:, 0], ddof=1)) if course != "all" and len(a) > 1 else math.nan
        print(
            f"{tag:<6}{course:<10}{name:>22}  {a[:, 0].mean():>10.4f} {a[:, 1].mean():>8.4f} {change:>+6.0f}% "
            f"{100.0 * (a[:, 1] - a[:, 0]).max():>+8.2f} {noise:>8.2f} {worse:>6}/{len(a):<3} "
            f"{a[:, 3].sum() / a[:, 2].sum():>10.2f}  {a[:, 4].mean():>9.4f} {a[:, 5].mean():>8.4f} "
            f"{end_change:>+6.0f}%"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--draws", choices=DRAWS, default="shared", help="IMU error draws per walk (DRAWS)")
    ap.add_argument("--duration", type=float, default=90.0)
    ap.add_argument("--courses", default=",".join(COURSES), help="comma-separated, of " + ", ".join(COURSES))
    ap.add_argument("--axes", default=",".join(AXES), help="axis errors, comma-separated, of " + ", ".join(AXES))
    ap.add_argument("--bounds", default="1.2", help="R values, m, comma-separated")
    ap.add_argument("--variants", default="default", help=f"comma-separated, of {', '.join(VARIANTS)}")
    ap.add_argument("--heading-sigma", type=float, default=None, help="σ of the relative heading, degrees")
    ap.add_argument("--heading-drift", type=float, default=None, help="heading drift per stride, degrees")
    ap.add_argument("--heading-drift-per-turn", type=float, default=None, help="heading drift per turn")
    ap.add_argument("--heading-band", type=float, default=None, help="the relative heading's band, degrees")
    args = ap.parse_args(argv)
    bounds = [float(b) for b in args.bounds.split(",")]
    heading = RelativeHeading()
    if args.heading_sigma is not None:
        heading = dataclasses.replace(heading, sigma_rad=math.radians(args.heading_sigma))
    if args.heading_drift is not None:
        heading = dataclasses.replace(heading, drift_rad=math.radians(args.heading_drift))
    if args.heading_drift_per_turn is not None:
        heading = dataclasses.replace(heading, drift_per_turn=args.heading_drift_per_turn)
    if args.heading_band is not None:
        heading = dataclasses.replace(heading, band_rad=math.radians(args.heading_band))
    variants = couplings(args.variants.split(","), bounds, heading)
    courses, axes_list = args.courses.split(","), args.axes.split(",")
    if not set(courses) <= set(COURSES) or not set(axes_list) <= set(AXES):
        raise SystemExit(f"courses: of {', '.join(COURSES)}; axes: of {', '.join(AXES)}")
    warm = walk_signals("line", 1, 10.0, "none")[1]
    navigate_feet(warm[0], warm[1], coupling=FootSeparation(heading=RelativeHeading()))  # compile first
    main_r = next(iter(variants))
    print(f"two feet, {args.duration:.0f} s walks, mpu6500x4; horizontal error, m (L/R); coupled: {main_r}")
    hdr = f"{'axes':<6}{'course':<10}{'seed':>4}  {'indep end':>11} {'indep mean':>11}  "
    print(hdr + f"{'coupled end':>11} {'cpl mean':>11} {'updates':>7} {'change':>7}")
    summary: dict[tuple[str, str, str], list[Walk]] = {}
    for axes in axes_list:
        tag = "none" if axes == "none" else "axes"
        for course in courses:
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                r = run(course, seed, args.duration, axes, variants, args.draws)
                fl, fr, ml, mr, ti, _ = r["ind"]
                ind_mean = 0.5 * (ml + mr)
                for name in [*variants, CEILING]:
                    cfl, cfr, cml, cmr, tc, nc = r[name]
                    cpl_mean = 0.5 * (cml + cmr)
                    for group in (course, "all"):
                        walk = (ind_mean, cpl_mean, ti, tc, 0.5 * (fl + fr), 0.5 * (cfl + cfr))
                        summary.setdefault((tag, group, name), []).append(walk)
                    if name == main_r:
                        change = 100.0 * (cpl_mean / ind_mean - 1.0)
                        print(
                            f"{tag:<6}{course:<10}{seed:>4}  {fl:>5.2f}/{fr:<5.2f} {ml:>5.2f}/{mr:<5.2f}  "
                            f"{cfl:>5.2f}/{cfr:<5.2f} {cml:>5.2f}/{cmr:<5.2f} {nc:>7} {change:>+6.0f}%"
                        )
    print()
    summarize(dict(sorted(summary.items(), key=lambda kv: (kv[0][0], kv[0][1] == "all"))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
