"""``footnav experiment tof``: foot clearance and height from the ToF sensors, with and without them.

For each walk (the paper's 70 s walk, here the emulator's rectangle course, and the stair course) one
recording is made: the emulated IMU (``mpu6500x4`` noise and biases, and by default the axis errors
of a unit whose gyroscope had only its bias calibrated, as the platform's: ``gyro-bias-calibrated``
in :data:`footnav.device.emulator.sensors.imu_errors.AXIS_ERRORS`; ``--axis-errors none`` for the noise and biases
alone) and the emulated ToF sensors (``footnav.device.emulator.sensors.tof``). With no axis errors, zero-
velocity updates alone lose only millimetres of height in 70 s (0.1-2.7 cm RMS at footfalls, seeds
1-8), far less than on real recordings with ZUPT alone; with the gyroscope's datasheet scale and
cross-axis tolerances they lose 2.5-124 cm, the real recordings' order. The same recording is navigated
twice by the same navigator: with the ToF channel, and with it removed (zero-velocity updates alone), so the gain is
measured side by side. Figures against the emulator's ground truth:

- clearance RMS: estimated clearance (``NavBatch.clearance_m``) minus the true height of the IMU above
  the floor under it, over every navigated sample; live, and from each swing's hits past and future
  (:mod:`footnav.pipeline.gait.tof_clearance`, what replay and evaluation can do);
- vertical error at footfalls (the accumulated error): RMS and maximum of the z error over the true
  stance samples, and the z error at the end;
- horizontal error: RMS over stance samples and at the end;
- readings by what became of them (used, each gate's reason, each invalid status).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass

import numpy as np
from footnav.device.emulator.motion.floors import floor_of
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.device.emulator.sensors.imu_errors import AXIS_ERRORS, IMU_GRADES, corrupt
from footnav.device.emulator.sensors.tof import TofSensorModel, tof_readings
from footnav.pipeline.aiding.tof_types import CODE_NAMES, STATUS_NAMES, RangeBatch, TofConfig
from footnav.pipeline.gait.tof_clearance import swing_clearance
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavConfig, navigate
from footnav.pipeline.navigation.profiles import get_profile

WALKS: tuple[tuple[str, float], ...] = (("rectangle", 70.0), ("line", 70.0), ("stairs", 70.0))
"""(course, duration s) of the experiment's walks."""

AXES = "gyro-bias-calibrated"
"""The emulated unit's axis errors (a key of :data:`footnav.device.emulator.sensors.imu_errors.AXIS_ERRORS`)."""


@dataclass(frozen=True)
class Recording:
    """One emulated recording: truth, corrupted IMU and the ToF readings."""

    truth: GaitTruth
    acc_b_mps2: np.ndarray
    gyr_b_radps: np.ndarray
    ranges: RangeBatch


@dataclass(frozen=True)
class RunFigures:
    """Errors of one navigation of a recording (see the module docstring), metres."""

    clearance_rms_m: float
    swing_clearance_rms_m: float
    """From each swing's hits past and future (NaN without ToF)."""
    z_stance_rms_m: float
    z_stance_max_m: float
    z_final_m: float
    xy_stance_rms_m: float
    xy_final_m: float
    readings: dict[str, int]


def record(
    path: str, duration_s: float, seed: int = 1, sensors: TofSensorModel | None = None, axes: str = AXES
) -> Recording:
    """The emulated recording of one walk (seeded; ``axes``: a key of ``AXIS_ERRORS``)."""
    truth = simulate_walk(path, duration_s, rate_hz=1000.0, seed=seed)
    acc, gyr, _ = corrupt(
        truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, IMU_GRADES["mpu6500x4"], seed=seed, axes=axes
    )
    script = tof_readings(
        truth.t_s, truth.pos_n_m, truth.quat_nb_wxyz, floor_of(path), sensors or TofSensorModel(seed=seed)
    )
    return Recording(truth, acc, gyr, RangeBatch(script.t_s, script.sensor, script.range_m, script.status))


def figures(truth: GaitTruth, nav: NavBatch, readings: dict[str, int], snap_m: float | None = None) -> RunFigures:
    """Errors of the estimates ``nav`` (the last ``len(nav)`` samples of the recording); ``snap_m``:
    ``TofConfig.snap_m`` of the run (default: the default's)."""
    first = len(truth) - len(nav)
    pos_true = truth.pos_n_m[first:]
    err = nav.pos_n_m - pos_true
    still = truth.stance[first:]
    clearance_true = pos_true[:, 2] - truth.floor_z_m[first:]
    clearance_err = nav.clearance_m - clearance_true
    swing_rms = math.nan
    if nav.ranges is not None:
        snap = TofConfig().snap_m if snap_m is None else snap_m
        swing = swing_clearance(nav.t_s, nav.pos_n_m, nav.stance, nav.clearance_m, nav.ranges, snap)
        swing_rms = float(np.sqrt(np.mean((swing - clearance_true) ** 2)))
    xy = np.hypot(err[:, 0], err[:, 1])
    return RunFigures(
        clearance_rms_m=float(np.sqrt(np.mean(clearance_err**2))),
        swing_clearance_rms_m=swing_rms,
        z_stance_rms_m=float(np.sqrt(np.mean(err[still, 2] ** 2))),
        z_stance_max_m=float(np.max(np.abs(err[still, 2]))),
        z_final_m=float(abs(err[-1, 2])),
        xy_stance_rms_m=float(np.sqrt(np.mean(xy[still] ** 2))),
        xy_final_m=float(xy[-1]),
        readings=readings,
    )


def compare(rec: Recording, tof: TofConfig | None = None) -> tuple[RunFigures, RunFigures]:
    """(ZUPT alone, with ToF) figures for the same recording, one navigator configuration. ZUPT alone
    is the inertial-only filter without its stance height constraint (``footnav.pipeline.stance.levels``,
    which the ToF floor levels replace): zero-velocity aiding, the baseline of the ToF figures."""
    t = rec.truth
    config = NavConfig(profile=get_profile("mpu6500x4"), stance_levels=False)
    out = []
    for ranges in (None, rec.ranges):
        nav, _ = navigate(t.t_s, rec.acc_b_mps2, rec.gyr_b_radps, t.rate_hz, config, ranges=ranges, tof=tof)
        if nav is None:
            raise RuntimeError("the navigator never aligned on the emulated walk")
        counts = {} if nav.ranges is None else _counts(nav)
        out.append(figures(t, nav, counts, (tof or TofConfig()).snap_m))
    return out[0], out[1]


def _counts(nav: NavBatch) -> dict[str, int]:
    """Readings of a navigated recording by what became of them (invalid ones by their status)."""
    r = nav.ranges
    assert r is not None
    counts: dict[str, int] = {}
    for code, status in zip(r.code.tolist(), r.status.tolist(), strict=True):
        name = STATUS_NAMES.get(status, CODE_NAMES[code]) if status else CODE_NAMES[code]
        counts[name] = counts.get(name, 0) + 1
    return counts


def table(rows: list[tuple[str, RunFigures, RunFigures]]) -> list[str]:
    """The experiment's table, one line per walk and run, in cm."""
    head = (
        f"{'walk':<16}{'run':<10}{'clearance':>10}{'swing':>8}{'z stance':>10}{'z max':>8}{'z end':>8}"
        f"{'xy stance':>11}{'xy end':>8}   readings"
    )
    lines = [head, f"{'':<26}{'RMS cm':>10}{'RMS cm':>8}{'RMS cm':>10}{'cm':>8}{'cm':>8}{'RMS cm':>11}{'cm':>8}"]
    for walk, zupt, tof in rows:
        for label, f in (("ZUPT", zupt), ("ZUPT+ToF", tof)):
            counts = ", ".join(f"{k} {v}" for k, v in sorted(f.readings.items(), key=lambda kv: -kv[1]))
            lines.append(
                f"{walk:<16}{label:<10}{100 * f.clearance_rms_m:>10.2f}{_cm(f.swing_clearance_rms_m):>8}"
                f"{100 * f.z_stance_rms_m:>10.2f}"
                f"{100 * f.z_stance_max_m:>8.2f}{100 * f.z_final_m:>8.2f}{100 * f.xy_stance_rms_m:>11.2f}"
                f"{100 * f.xy_final_m:>8.2f}   {counts or '-'}"
            )
        ratio = zupt.z_stance_rms_m / max(tof.z_stance_rms_m, 1e-12)
        lines.append(f"{'':<16}vertical error at footfalls {ratio:.1f}x lower with ToF")
    return lines


def _cm(v_m: float) -> str:
    return "-" if math.isnan(v_m) else f"{100 * v_m:.2f}"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=int, default=1, help="emulator seed (default 1)")
    parser.add_argument("--duration", type=float, default=None, help="seconds per walk (default 70)")
    parser.add_argument(
        "--axis-errors",
        choices=sorted(AXIS_ERRORS),
        default=AXES,
        help=f"scale-factor and cross-axis errors of the emulated IMU (default {AXES})",
    )


def run(args: argparse.Namespace) -> int:
    rows = []
    print(f"emulated IMU: mpu6500x4 noise and biases, axis errors {args.axis_errors!r}, seed {args.seed}")
    for path, duration_s in WALKS:
        rec = record(path, args.duration or duration_s, seed=args.seed, axes=args.axis_errors)
        zupt, tof = compare(rec)
        rows.append((f"{path} {args.duration or duration_s:.0f} s", zupt, tof))
    for line in table(rows):
        print(line)
    return 0
