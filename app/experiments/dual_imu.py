"""The dual-IMU board against single-IMU ZUPT on the paper's two courses (issue 6).

For each course (the 18 × 9 m rectangle walked once round; the stair course: 24 steps of
0.343 m × 0.16 m up, the 6.415 × 1.26 m landing, and back down) and each seed, the emulator walks a
dual-IMU board (lever arm 1 cm, 1 cm, 0; two ICM-20948-class IMUs with independent errors) and
the filters navigate the same record with the same stance samples (footnav's SHOE detector with
its adaptive threshold, run on IMU 1):

- ``single``: footnav's 15-state ESKF (ZUPT + χ²-gated ZARU, both biases estimated) on IMU 1;
- ``classic``: the same filter with its bias states frozen (the classic 9-state OpenShoe ZUPT
  filter: position, velocity, attitude; Nilsson et al. 2012), the gyro bias fixed at IMU 1's mean
  rate over the first second of standing (the start-up calibration the paper filter gets too);
- ``paper``: the reconstructed filter of Chen et al. (2022), :mod:`footnav.pipeline.dual_imu.chen2022`;
- ``paper-3c``: the same filter on the stance samples of the paper's own three-condition detector
  (:mod:`footnav.pipeline.stance.combined`) instead of the shared SHOE ones;
- ``footnav``: footnav's rigid-board dual-IMU ESKF, :mod:`footnav.pipeline.dual_imu.board_eskf`;
- ``foot2foot``: the paper's second reference, one IMU on each foot and the feet's filters bounded by
  their largest separation (:mod:`footnav.pipeline.two_feet`, R = 1.2 m; Skog et al. 2012), on the two
  feet of a walker of the same course (``two_feet_walks``, IMUs of the same grade, the left foot scored).

``--paper-setup`` emulates the paper's own hardware instead of footnav's default board: uncalibrated
ICM-20948s (:data:`PAPER_SETUP`: datasheet sensitivity, cross-axis and board-level zero-g tolerances)
at 100 Hz, their readings saturated at ±8 g and ±1000 °/s and quantised to 16 bits.

Errors are 3D distances from IMU 1's (foot2foot: the left foot's) true position at every sample; per
run the maximum and the mean, then averaged over the seeds. Every filter is zero-velocity aiding alone: the single-IMU
navigator's stance height constraint (``footnav.pipeline.stance.levels``), which the dual-IMU filter does not
have, is off, so the table measures what the second IMU adds.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
from footnav.device.emulator.motion.gait import two_feet_walks
from footnav.device.emulator.sensors.dual_imu import (
    DEFAULT_GRADE,
    DEFAULT_LEVER_B_M,
    DualImuRecording,
    one_lap_duration_s,
    simulate_dual_imu,
)
from footnav.device.emulator.sensors.imu_errors import (
    AXIS_ERRORS,
    ICM20948_PAPER_RANGE,
    STANDARD_GRAVITY_MPS2,
    FullScale,
    corrupt,
)
from footnav.pipeline.dual_imu.board_eskf import DualEskfConfig, DualEskfTrack, run_dual_eskf
from footnav.pipeline.dual_imu.chen2022 import DualTrack, PaperConfig, run_paper
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation.alignment import align_from_still
from footnav.pipeline.navigation.batches import NO_CLIPPED_RATES, zupt_ratio
from footnav.pipeline.navigation.navigator import NavConfig, filter_parameters, navigate
from footnav.pipeline.navigation.profiles import UnitProfile, get_profile
from footnav.pipeline.stance.combined import combined_stance
from footnav.pipeline.stance.detectors import StreamingDetector
from footnav.pipeline.two_feet import FootSeparation, FootSignals, navigate_feet
from footnav.views.dual_imu import DualRunView, save_dual_runs
from numpy.typing import NDArray

F64 = NDArray[np.float64]


COURSES: Final = ("rectangle", "stairs")
BOARD_METHODS: Final = ("single", "classic", "paper", "paper-3c", "footnav")
"""The methods that navigate the dual-IMU board's record."""
METHODS: Final = (*BOARD_METHODS, "foot2foot")
LABELS: Final = {
    "single": "single-IMU ZUPT: footnav 15-state ESKF (ZUPT + gated ZARU, biases estimated), IMU 1",
    "classic": "classic ZUPT: the same filter, bias states frozen (OpenShoe 9-state), IMU 1; gyro bias = mean "
    "rate of the first 1 s still (the paper filter's start-up calibration), accelerometer bias 0",
    "paper": "paper (Chen et al. 2022, reconstructed): linear KF [r1 r2 v1 v2], eqs. 17-19",
    "paper-3c": "the paper's filter on the stance samples of its own three-condition detector (acceleration "
    "magnitude and variance, angular rate; its section 3) instead of SHOE",
    "footnav": "footnav dual: rigid-board ESKF on both IMUs, both bias sets, rigid-body constraints",
    "foot2foot": "foot-to-foot: an IMU on each foot, footnav's filter on each, coupled by the inter-foot distance "
    "bound R = 1.2 m (the paper's second reference); the left foot, on its own two-feet walk of the course",
}
PROFILE: Final = "generic"
"""The filters' noise model: a single ICM-20948-class part (``footnav.pipeline.navigation.profiles``)."""
DEFAULT_SEEDS: Final = 8


@dataclass(frozen=True, slots=True)
class BoardSetup:
    """The emulated IMUs: every IMU of a run (both on the board, one on each foot) alike, errors drawn
    independently.

    Attributes
    ----------
    grade
        ``imu_errors.IMU_GRADES`` key: noise and biases.
    axes
        ``imu_errors.AXIS_ERRORS`` key: scale-factor and cross-axis errors.
    rate_hz
        Sample rate, Hz.
    full_scale
        Output range and ADC (None: unbounded, unquantised).
    """

    grade: str = DEFAULT_GRADE
    axes: str = "none"
    rate_hz: float = 1000.0
    full_scale: FullScale | None = None

    def describe(self) -> str:
        """One line for the table's footer."""
        fs = self.full_scale
        rng = "unbounded"
        if fs is not None:
            rng = f"±{fs.acc_mps2 / STANDARD_GRAVITY_MPS2:g} g, ±{math.degrees(fs.gyr_radps):g} °/s, {fs.bits}-bit"
        return f"IMUs: {self.grade} grade at {self.rate_hz:g} Hz, axis errors {self.axes!r}, range {rng}"


PAPER_SETUP: Final = BoardSetup(
    grade="icm20948-board", axes="icm20948-datasheet", rate_hz=100.0, full_scale=ICM20948_PAPER_RANGE
)
"""The paper's hardware (Chen et al. 2022): ICM-20948s at 100 Hz, ±8 g, ±1000 °/s,
uncalibrated but for the gyroscope's start-up bias (``imu_errors``: grade ``icm20948-board``, axis
errors ``icm20948-datasheet``)."""


def classic_profile(profile: UnitProfile) -> UnitProfile:
    """``profile`` with the bias states frozen: zero prior and zero random walk (a 9-state filter)."""
    return dataclasses.replace(
        profile,
        acc_bias_init_mps2=1e-12,
        gyr_bias_init_radps=1e-12,
        acc_bias_rw_mps3_rthz=0.0,
        gyr_bias_rw_radps2_rthz=0.0,
    )


def classic_track(
    t_s: F64, acc_b_mps2: F64, gyr_b_radps: F64, stance: NDArray[np.bool_], rate_hz: float, config: NavConfig
) -> F64:
    """(n, 3) positions of the classic 9-state ZUPT filter: footnav's ESKF kernel with the bias states
    frozen (zero prior and random walk), the given stance samples, and the gyro bias fixed at the mean
    rate over the first ``PaperConfig.align_s`` of standing (the start-up calibration the paper filter
    gets too), aligned on the same window."""
    window = slice(0, round(PaperConfig().align_s * rate_hz))
    al = align_from_still(acc_b_mps2[window], gyr_b_radps[window])
    x = np.zeros(16)
    x[6:10] = al.quat_nb_wxyz
    x[13:16] = gyr_b_radps[window].mean(axis=0)
    tilt, yaw = config.init_tilt_sigma_rad, config.init_yaw_sigma_rad
    sig = np.concatenate(
        [np.full(3, config.init_pos_sigma_m), np.full(3, config.init_vel_sigma_mps), [tilt, tilt, yaw], np.zeros(6)]
    )
    P = np.diag(sig**2)
    par = filter_parameters(classic_profile(config.profile), rate_hz, al.gravity_mps2, config.dt_max_s)
    n = t_s.shape[0]
    pos, vel, quat, cov = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4, 4))
    dt = np.diff(t_s, prepend=t_s[0] - 1.0 / rate_hz)
    counters = np.zeros(eskf.N_CNT, dtype=np.int64)
    # T/γ = 0: the same zero-velocity noise on every axis, as the classic filter has it
    eskf.run_filter(
        x, P, acc_b_mps2, gyr_b_radps, NO_CLIPPED_RATES, dt, np.ascontiguousarray(stance), np.zeros(n), par,
        pos, vel, quat, cov, counters,
    )  # fmt: skip
    return pos


@dataclass(frozen=True, slots=True)
class RunResult:
    """One course, one seed: the record, each method's IMU-1 track, and its errors.

    Attributes
    ----------
    recording
        the emulated dual-IMU walk.
    stance
        (n,) the shared detector output.
    pos1_n_m
        method -> (n, 3) IMU 1's estimated position (NaN before a method could start).
    max_error_m, mean_error_m
        method -> error against IMU 1's truth, m.
    paper
        the paper filter's full output.
    footnav
        footnav's.
    """

    recording: DualImuRecording
    stance: NDArray[np.bool_]
    pos1_n_m: dict[str, F64]
    max_error_m: dict[str, float]
    mean_error_m: dict[str, float]
    paper: DualTrack
    footnav: DualEskfTrack


def evaluate_run(
    course: str,
    seed: int,
    *,
    lever_b_m: tuple[float, float, float] = DEFAULT_LEVER_B_M,
    setup: BoardSetup = BoardSetup(),
) -> RunResult:
    """Walk ``course`` once with seed ``seed`` on the IMUs of ``setup`` and navigate it with every method."""
    rec = simulate_dual_imu(
        course,
        seed=seed,
        lever_b_m=lever_b_m,
        grade=setup.grade,
        axes=setup.axes,
        rate_hz=setup.rate_hz,
        full_scale=setup.full_scale,
    )
    profile = get_profile(PROFILE)
    nav_config = NavConfig(profile=profile, stance_levels=False)
    acc1 = np.ascontiguousarray(rec.acc_b_mps2[:, 0])
    gyr1 = np.ascontiguousarray(rec.gyr_b_radps[:, 0])
    stat, threshold, stance = StreamingDetector(nav_config.detector, rec.rate_hz).update(acc1, gyr1)
    n = len(rec.t_s)
    tracks: dict[str, F64] = {}
    nav, _ = navigate(rec.t_s, acc1, gyr1, rec.rate_hz, nav_config)
    pos = np.full((n, 3), np.nan)
    if nav is not None:
        pos[n - len(nav) :] = nav.pos_n_m
        if not np.array_equal(nav.stance, stance[n - len(nav) :]):
            raise AssertionError("the navigator's detector disagrees with the shared one")  # pragma: no cover
    tracks["single"] = pos
    tracks["classic"] = classic_track(rec.t_s, acc1, gyr1, stance, rec.rate_hz, nav_config)
    lever = np.asarray(lever_b_m, dtype=np.float64)
    paper = run_paper(
        rec.t_s, rec.acc_b_mps2, rec.gyr_b_radps, stance, lever, rec.rate_hz, PaperConfig(profile=profile)
    )
    footnav = run_dual_eskf(
        rec.t_s,
        rec.acc_b_mps2,
        rec.gyr_b_radps,
        stance,
        lever,
        rec.rate_hz,
        DualEskfConfig(profile=profile),
        zupt_ratio(stat, threshold),
    )
    tracks["paper"] = paper.pos1_n_m
    stance_3c = combined_stance(acc1, gyr1, rec.rate_hz)
    tracks["paper-3c"] = run_paper(
        rec.t_s, rec.acc_b_mps2, rec.gyr_b_radps, stance_3c, lever, rec.rate_hz, PaperConfig(profile=profile)
    ).pos1_n_m
    tracks["footnav"] = footnav.pos1_n_m
    truth = rec.truth.imu1.pos_n_m
    errors = {m: np.linalg.norm(tracks[m] - truth, axis=1) for m in BOARD_METHODS}
    errors["foot2foot"] = foot_to_foot_errors(course, seed, setup, nav_config)
    return RunResult(
        recording=rec,
        stance=stance,
        pos1_n_m=tracks,
        max_error_m={m: float(np.nanmax(e)) for m, e in errors.items()},
        mean_error_m={m: float(np.nanmean(e)) for m, e in errors.items()},
        paper=paper,
        footnav=footnav,
    )


def foot_to_foot_errors(course: str, seed: int, setup: BoardSetup, config: NavConfig) -> F64:
    """(n,) 3D error of the left foot at every sample, m, of one lap of ``course`` walked by two feet, each
    with its own IMU of ``setup`` (independent errors), navigated coupled by the distance bound."""
    _, lap_s = one_lap_duration_s(course, 1.4, 3.0)
    gait_seed, seed_l, seed_r = (int(s.generate_state(1)[0]) for s in np.random.SeedSequence([seed, 2]).spawn(3))
    feet = two_feet_walks(course, lap_s, setup.rate_hz, seed=gait_seed)
    signals = []
    for truth, imu_seed in zip(feet, (seed_l, seed_r), strict=True):
        acc, gyr, _ = corrupt(
            truth.acc_b_mps2,
            truth.gyr_b_radps,
            truth.rate_hz,
            setup.grade,
            imu_seed,
            axes=setup.axes,
            full_scale=setup.full_scale,
        )
        signals.append(FootSignals(truth.t_s, acc, gyr, truth.rate_hz))
    result = navigate_feet(signals[0], signals[1], config, FootSeparation(heading=None))  # the bound alone
    left = feet[0].pos_n_m
    err = np.full(left.shape[0], np.nan)
    if result.left is not None:
        err[left.shape[0] - len(result.left) :] = np.linalg.norm(
            result.left.pos_n_m - left[-len(result.left) :], axis=1
        )
    return err


@dataclass(frozen=True, slots=True)
class TableRow:
    """Seed-averaged errors of one method on one course, m, and the mean error's ratios."""

    course: str
    method: str
    max_error_m: float
    mean_error_m: float
    ratio_to_single: float
    ratio_to_classic: float
    ratio_to_foot2foot: float


def error_table(
    seeds: list[int],
    courses: tuple[str, ...] = COURSES,
    *,
    first_runs: dict[str, RunResult] | None = None,
    setup: BoardSetup = BoardSetup(),
) -> list[TableRow]:
    """Run every course and seed; average the per-run max and mean errors over the seeds.

    ``first_runs``, if given, receives each course's run of the first seed (for the recording).
    """
    rows: list[TableRow] = []
    for course in courses:
        runs = [evaluate_run(course, s, setup=setup) for s in seeds]
        if first_runs is not None:
            first_runs[course] = runs[0]
        mx = {m: float(np.mean([r.max_error_m[m] for r in runs])) for m in METHODS}
        mean = {m: float(np.mean([r.mean_error_m[m] for r in runs])) for m in METHODS}
        rows.extend(
            TableRow(
                course,
                m,
                mx[m],
                mean[m],
                mean[m] / mean["single"],
                mean[m] / mean["classic"],
                mean[m] / mean["foot2foot"],
            )
            for m in METHODS
        )
    return rows


def format_table(rows: list[TableRow], seeds: list[int], setup: BoardSetup = BoardSetup()) -> str:
    """The table as text, with the methods spelled out underneath."""
    lines = [
        f"position error of IMU 1 (3D, every sample), mean over seeds {seeds[0]}..{seeds[-1]} ({len(seeds)} runs "
        "per course)",
        f"{'course':<10} {'method':<9} {'max m':>7} {'mean m':>7} {'mean/single':>12} {'mean/classic':>13} "
        f"{'mean/f2f':>10}",
    ]
    lines += [
        f"{r.course:<10} {r.method:<9} {r.max_error_m:7.3f} {r.mean_error_m:7.3f} {r.ratio_to_single:12.2f} "
        f"{r.ratio_to_classic:13.2f} {r.ratio_to_foot2foot:10.2f}"
        for r in rows
    ]
    lines.append("")
    lines += [f"{m:<9} {LABELS[m]}" for m in METHODS]
    lines.append(
        "same record and same stance samples (SHOE detector, adaptive threshold, on IMU 1) for all but paper-3c "
        "(its own detector) and foot2foot (its own two-feet walk); "
        f"{setup.describe()}, independent errors; "
        f"lever arm {DEFAULT_LEVER_B_M} m; "
        f"filter profile {PROFILE!r}"
    )
    return "\n".join(lines)


def _rate_hz(text: str) -> float:
    try:
        rate = float(text)
    except ValueError:
        rate = math.nan
    if not 10.0 <= rate <= 10_000.0:
        raise argparse.ArgumentTypeError(f"expected a sample rate of 10 to 10000 Hz, got {text!r}")
    return rate


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``footnav experiment dual-imu``."""
    parser.add_argument("--seeds", type=int, default=DEFAULT_SEEDS, help=f"runs per course (default {DEFAULT_SEEDS})")
    parser.add_argument("--first-seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument(
        "--save", type=Path, default=None, metavar="FILE.rrd", help="also write the first seed's runs to a recording"
    )
    parser.add_argument(
        "--axis-errors",
        choices=sorted(AXIS_ERRORS),
        default="none",
        help="scale-factor and cross-axis errors of both emulated IMUs (default none)",
    )
    parser.add_argument(
        "--rate",
        type=_rate_hz,
        default=1000.0,
        metavar="HZ",
        help="the emulated IMUs' sample rate (default 1000; the paper: 100)",
    )
    parser.add_argument(
        "--paper-setup",
        action="store_true",
        help="emulate the paper's own IMUs instead: uncalibrated ICM-20948s at 100 Hz, ±8 g, ±1000 °/s, 16-bit "
        "(overrides --rate and --axis-errors)",
    )


def run(args: argparse.Namespace) -> int:
    """Print the table (and write the recording with ``--save``)."""
    seeds = list(range(args.first_seed, args.first_seed + max(1, args.seeds)))
    runs: dict[str, RunResult] = {}
    setup = PAPER_SETUP if args.paper_setup else BoardSetup(axes=args.axis_errors, rate_hz=args.rate)
    rows = error_table(seeds, first_runs=runs, setup=setup)
    print(format_table(rows, seeds, setup))
    if args.save is not None:
        save_dual_runs(args.save, {c: view_of(r) for c, r in runs.items()})
        print(f"recording of seed {seeds[0]} written to {args.save} (open it with: rerun {args.save})")
    return 0


def view_of(run: RunResult) -> DualRunView:
    """What the recording shows of one run: the four IMU-1 tracks, each IMU's own track (paper
    filter: two independently integrated IMUs), truth, and the constraint residuals."""
    return DualRunView(
        t_s=run.recording.t_s,
        truth_n_m=run.recording.truth.imu1.pos_n_m,
        tracks_n_m=run.pos1_n_m,
        imu_tracks_n_m={"imu1": run.paper.pos_imu_n_m[:, 0], "imu2": run.paper.pos_imu_n_m[:, 1]},
        residuals={
            "paper_rel_pos_mm": run.paper.residual_pos_m * 1e3,
            "paper_rel_vel_mps": run.paper.residual_vel_mps,
            "footnav_rate_diff_dps": np.degrees(run.footnav.residual_rate_radps),
            "footnav_force_diff_mps2": run.footnav.residual_force_mps2,
        },
    )
