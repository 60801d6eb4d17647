"""The ``footnav`` command line's parser: every command and option, with no numerics, Rerun or command
module imported (those load when a command runs, ``footnav.app.cli``)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import TYPE_CHECKING

from footnav.app.choices import AXIS_ERRORS, IMU_GRADES, OUTPUT_MODES, PATHS, PROFILES, RECORDING_FORMATS, UNIT_MODELS

if TYPE_CHECKING:
    from typing import TypeAlias

    Commands: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]  # the sub-command table
    Options: TypeAlias = argparse._ActionsContainer  # a parser or an argument group


WALKING_SPEED_MPS = (1.2, 1.8)
"""Walking speeds the emulator's gait model covers, m/s (``footnav.device.emulator.motion.gait.SPEED_RANGE_MPS``:
the parser imports no numerics, a test checks the two agree)."""
MAX_DEMO_DURATION_S = 3600.0
"""The longest demo walk, s: the demo computes the whole walk and its sensor signals before it starts (about
70 MB of memory a minute per foot), so an hour already takes some 4 GB a foot."""
MAX_IMU_MASK = 0x0F
"""The raw output's IMU mask covers the four IMUs of the largest supported board (``footnav.device.models``)."""


# Every argument type raises ``ArgumentTypeError`` with what it expected, so that argparse says
# "argument --speed: expected a positive number, got 'abc'" and never the function's name.
def _number(text: str, expected: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None


def _positive(text: str) -> float:
    value = _number(text, "a positive number")
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _finite(text: str) -> float:
    value = _number(text, "a number")
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _pace(text: str) -> float:
    if text == "max":
        return math.inf
    value = _number(text.removesuffix("x"), "1x, Nx (N > 0) or max")
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected 1x, Nx (N > 0) or max, got {text!r}")
    return value


def _seconds(text: str) -> float:
    value = _number(text, "a time in seconds, >= 0")
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"expected a time in seconds, >= 0, got {text!r}")
    return value


def _wait_seconds(text: str) -> float:
    # a wait must end: liblsl returns at once from an infinite timeout, so `inf` would not wait at all
    value = _number(text, "a finite time in seconds, >= 0")
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite time in seconds, >= 0, got {text!r}")
    return value


def _walking_speed(text: str) -> float:
    lo, hi = WALKING_SPEED_MPS
    expected = f"a walking speed from {lo} to {hi} m/s (what the emulated gait covers)"
    value = _number(text, expected)
    if not lo <= value <= hi:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return value


def _demo_duration(text: str) -> float:
    expected = (
        f"a duration over 0 and at most {MAX_DEMO_DURATION_S:.0f} s (the demo computes the whole walk in "
        "memory before it starts, about 70 MB a minute per foot)"
    )
    value = _number(text, expected)
    if not 0 < value <= MAX_DEMO_DURATION_S:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f"expected a whole number from 0 to 2**32 - 1, got {text!r}")
    return value


def _imu_mask(text: str) -> int:
    expected = f"an IMU mask from 0x01 to 0x{MAX_IMU_MASK:02X}, e.g. 0x0F (one bit per IMU)"
    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
    if not 0 < value <= MAX_IMU_MASK:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
    return value


def _add_stance_arg(p: argparse.ArgumentParser, *, default: str | None) -> None:
    """``--stance``: the zero-velocity detector of ToF units (``footnav.pipeline.stance.height_detector``)."""
    p.add_argument(
        "--stance", choices=("inertial", "height", "and", "or"), default=default,
        help="ToF units: stance from the inertial detector, from the foot's height and angular rate, "
        "or both (and/or); default: inertial" + ("" if default else ", or as recorded"),
    )  # fmt: skip


def _add_config_args(p: argparse.ArgumentParser, *, profile: bool = True) -> None:
    p.add_argument(
        "--config", type=Path, metavar="FILE", help="configuration file (default: ./footnav.toml if present)"
    )
    if profile:
        p.add_argument("--profile", metavar="NAME", help=f"unit noise profile: {', '.join(PROFILES)}, [profiles.NAME]")


def _add_step_smoothing_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--step-smoothing", action="store_true", default=None,
        help="also show each step smoothed once it has ended ([filter] step_smoothing)",
    )  # fmt: skip


def _add_feet_coupling_args(p: argparse.ArgumentParser, *, default: str) -> argparse._ArgumentGroup:
    feet = p.add_argument_group("two feet", f"how a left and a right foot are navigated (default: {default})")
    feet.add_argument(
        "--independent-feet",
        action="store_true",
        help="navigate each foot on its own (default: coupled by the inter-foot distance bound and relative heading)",
    )
    feet.add_argument(
        "--distance-only",
        action="store_true",
        help="couple the feet by the inter-foot distance bound alone, not by their relative heading in stance too",
    )
    _add_couple_heading_arg(feet)
    return feet


def _add_couple_heading_arg(feet: argparse._ArgumentGroup) -> None:
    # the relative heading is the default now; the flag that asked for it is still accepted
    feet.add_argument("--couple-heading", action="store_true", help=argparse.SUPPRESS)


def _add_lever_arm_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--lever-arm",
        type=_finite,
        nargs=3,
        default=None,
        metavar=("X", "Y", "Z"),
        help="with --dual-imu: IMU 2's position in IMU 1's axes, m (default 0.01 0.01 0)",
    )


def _add_output_args(p: argparse.ArgumentParser, *, capture: bool) -> None:
    p.add_argument("--save", type=Path, metavar="FILE.rrd", help="also write the recording to this file")
    p.add_argument("--no-viewer", action="store_true", help="no viewer (Rerun output only to a --save file)")
    p.add_argument("--web", action="store_true", help="serve the web viewer on 127.0.0.1 and print its URL")
    p.add_argument(
        "--keep-web",
        action="store_true",
        help="with --web: leave the web viewer serving after the session ends (its pid is printed; "
        "any local user can open it)",
    )
    p.add_argument(
        "--lsl",
        action="store_true",
        help="also stream each foot's navigation state and the gait events on Lab Streaming Layer "
        "(needs pylsl: pip install 'footnav[lsl]')",
    )
    p.add_argument(
        "--lsl-wait",
        type=_wait_seconds,
        default=0.0,
        metavar="S",
        help="with --lsl: before the first sample, wait up to S seconds for a consumer of every stream (default 0)",
    )
    if capture:
        p.add_argument("--sessions", type=Path, metavar="DIR", help="capture folder (default: ./sessions)")
        p.add_argument("--no-capture", action="store_true", help="do not write a capture file")


def build_parser() -> argparse.ArgumentParser:
    """The whole parser; it imports no numerics, Rerun or command module (those load when a command runs)."""
    parser = argparse.ArgumentParser(prog="footnav", description="Foot-mounted inertial navigation, live in Rerun.")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug detail to stderr")
    sub = parser.add_subparsers(dest="command", required=True)

    _add_demo_command(sub)
    _add_live_command(sub)
    _add_calibrate_command(sub)
    _add_scan_command(sub)
    _add_replay_command(sub)
    _add_export_command(sub)
    _add_evaluate_command(sub)
    _add_experiment_command(sub)
    _add_config_command(sub)
    return parser


def _add_demo_command(sub: Commands) -> None:
    demo = sub.add_parser("demo", help="run everything against the built-in emulated shoe (no hardware)")
    demo.add_argument("--path", choices=PATHS, default="rectangle", help="walking path (default: rectangle, 18 × 9 m)")
    demo.add_argument(
        "--duration",
        type=_demo_duration,
        default=60.0,
        metavar="S",
        help=f"walk duration in seconds, at most {MAX_DEMO_DURATION_S:.0f} (default 60)",
    )
    demo.add_argument(
        "--speed", type=_walking_speed, default=1.4, metavar="M/S", help="walking speed, 1.2-1.8 m/s (default 1.4)"
    )
    demo.add_argument(
        "--grade",
        choices=IMU_GRADES,
        default=None,
        help="emulated sensor grade (default mpu6500x4; icm20948 with --dual-imu; the unit's IMU with --unit)",
    )
    demo.add_argument(
        "--axis-errors",
        choices=AXIS_ERRORS,
        default=None,
        help="scale-factor and cross-axis errors of the emulated IMU (default none; with --tof "
        "gyro-bias-calibrated, the multi-sensor platform's unit: its gyroscope had only its bias calibrated and "
        "keeps its datasheet scale and cross-axis tolerances)",
    )
    _add_output_args(demo, capture=True)
    _add_config_args(demo)
    _add_step_smoothing_arg(demo)
    _add_stance_arg(demo, default="inertial")
    _add_feet_coupling_args(demo, default="coupled, with --feet 2")
    demo.add_argument("--feet", type=int, choices=(1, 2), default=1, help="emulated shoes: 1, or 2 (left and right)")
    demo.add_argument(
        "--unit",
        type=str.lower,
        choices=UNIT_MODELS,
        metavar="MODEL",
        help=f"emulate a unit of this model ({', '.join(UNIT_MODELS)}: its base rate, command set, outputs and "
        "IMU) and run `footnav live --unit MODEL` on it",
    )
    demo.add_argument(
        "--mode",
        choices=OUTPUT_MODES,
        default="auto",
        help="with --unit: the output `live --mode` asks the emulated unit for (default: the best it offers)",
    )
    demo.add_argument(
        "--rate-divider", type=int, default=None, choices=range(15), metavar="K",
        help="with --unit: the rate divider `live --rate-divider` asks the emulated unit for",
    )  # fmt: skip
    demo.add_argument(
        "--imu-mask", type=_imu_mask, default=None, metavar="MASK",
        help="with --unit --mode raw: the IMUs the emulated unit streams and footnav averages (as live --imu-mask)",
    )  # fmt: skip
    demo.add_argument("--pace", type=_pace, default=1.0, metavar="1x|Nx|max", help="emulator speed (default real time)")
    demo.add_argument("--seed", type=_seed, default=1, help="random seed of the emulated sensor errors")
    demo.add_argument(
        "--miscalibrated",
        action="store_true",
        help="the emulated miscalibrated unit of `calibrate --demo` (its calibration applies if made)",
    )
    demo.add_argument(
        "--dual-imu",
        action="store_true",
        help="a dual-IMU board (two IMUs on one PCB, raw output 0x28, IMU mask 0b11) navigated by footnav's "
        "dual-IMU filter",
    )
    _add_lever_arm_arg(demo)
    demo.add_argument(
        "--board-lever-arm",
        type=_finite,
        nargs=3,
        default=None,
        metavar=("X", "Y", "Z"),
        help="with --dual-imu: where the emulated board really has IMU 2, m (default: --lever-arm); "
        "a different value shows the lever-arm check",
    )
    demo.add_argument(
        "--tof",
        action="store_true",
        help="emulate the multi-sensor unit: three ToF range sensors and a barometer, fused for foot clearance",
    )


def _add_live_command(sub: Commands) -> None:
    live = sub.add_parser("live", help="navigate one connected unit, or two (--left/--right), over USB serial or BLE")
    live.add_argument("--port", help="serial port of the unit, e.g. /dev/ttyACM0 (or ble:NAME)")
    live.add_argument(
        "--ble",
        nargs="?",
        const="",
        metavar="NAME|ADDRESS",
        help="the unit over Bluetooth LE, by advertised name or address (alone: the first unit found; "
        "`footnav scan` lists them)",
    )
    live.add_argument("--left", metavar="PORT|ble:NAME", help="the left-foot unit: serial port or ble:NAME")
    live.add_argument("--right", metavar="PORT|ble:NAME", help="the right-foot unit: serial port or ble:NAME")
    live.add_argument(
        "--tof",
        action="store_true",
        help="a ToF multi-sensor unit: switch on its ToF and barometer states, fuse the ranges",
    )
    live.add_argument(
        "--dual-imu",
        action="store_true",
        help="a dual-IMU board: stream both IMUs (raw output 0x28, mask 0b11) to the dual-IMU filter",
    )
    live.add_argument(
        "--unit",
        type=str.lower,
        choices=UNIT_MODELS,
        metavar="MODEL",
        help=f"the unit's model: {', '.join(UNIT_MODELS)} (sets its base rate, the modes it offers and its IMU's "
        "profile; default: a 1 kHz unit, its firmware probed)",
    )
    live.add_argument(
        "--mode",
        choices=OUTPUT_MODES,
        default="auto",
        help="imu: the unit's calibrated IMU output 0x40, navigated by footnav; raw: the raw registers 0x28 "
        "of the IMUs in --imu-mask, averaged into one IMU as the unit's own array firmware does; ins: the "
        "unit's own INS states and covariance; steps: the unit's stepwise dead reckoning, a step and its "
        "covariance per packet; auto (default): the best the unit offers (imu; steps on 2014 firmware)",
    )
    live.add_argument(
        "--imu-mask",
        type=_imu_mask,
        default=None,
        metavar="MASK",
        help="with --mode raw: the IMUs to stream and average (default 0x0F: the four of a MIMU board)",
    )
    _add_lever_arm_arg(live)
    _add_config_args(live)
    _add_step_smoothing_arg(live)
    _add_stance_arg(live, default="inertial")
    _add_feet_coupling_args(live, default="coupled, with --left and --right")
    live.add_argument(
        "--rate-divider",
        type=int,
        default=None,
        choices=range(15),
        metavar="K",
        help="output every 2**K samples of the unit's base rate, K = 0..14 (default 0 on serial, 2 on BLE; "
        "--mode ins: 2 on serial, 5 on BLE; 1 kHz, 250 Hz and 31.25 Hz on a 1 kHz unit); footnav navigates at "
        "the rate the unit's clock gives",
    )
    _add_output_args(live, capture=True)


def _add_calibrate_command(sub: Commands) -> None:
    cal = sub.add_parser(
        "calibrate",
        help="field calibration of the unit's IMU (icosahedron procedure); saved by MCU id, applied automatically",
    )
    cal_src = cal.add_mutually_exclusive_group(required=True)
    cal_src.add_argument("--port", help="serial port of the unit, e.g. /dev/ttyACM0")
    cal_src.add_argument(
        "--ble", nargs="?", const="", metavar="NAME|ADDRESS", help="the unit over Bluetooth LE (alone: the first found)"
    )
    cal_src.add_argument(
        "--capture", type=Path, metavar="FILE", help="fit from a capture recorded by an earlier `footnav calibrate`"
    )
    cal_src.add_argument(
        "--demo", action="store_true", help="an emulated miscalibrated unit that turns through the faces by itself"
    )
    cal.add_argument(
        "--imu-mask", type=_imu_mask, default=0x0F, metavar="MASK",
        help="IMUs whose raw outputs are averaged (default 0x0F: the four of a MIMU board)",
    )  # fmt: skip
    cal.add_argument(
        "--rate-divider", type=int, default=None, choices=range(7), metavar="K",
        help="raw output every 2**K samples of the 1 kHz base rate (default 0 on serial, 3: 125 Hz over BLE)",
    )  # fmt: skip
    cal.add_argument(
        "--hold", type=_positive, default=None, metavar="S",
        help="still time averaged per face (default 2 s at 1 kHz, 8 s at 125 Hz over BLE)",
    )  # fmt: skip
    cal.add_argument(
        "--no-temperature",
        action="store_true",
        help="if the temperature barely changes, fit the 9-parameter model without temperature terms",
    )
    cal.add_argument(
        "--pace", type=_pace, default=10.0, metavar="1x|Nx|max", help="--demo: emulator speed (default 10x)"
    )
    cal.add_argument("--sessions", type=Path, metavar="DIR", help="capture folder (default: ./sessions)")
    cal.add_argument("--no-capture", action="store_true", help="do not write a capture of the procedure")
    _add_config_args(cal, profile=False)


def _add_scan_command(sub: Commands) -> None:
    scan = sub.add_parser("scan", help="list serial ports and BLE devices that look like shoe units")
    scan.add_argument("--timeout", type=_positive, default=5.0, metavar="S", help="how long to scan BLE (default 5 s)")


def _add_replay_command(sub: Commands) -> None:
    replay = sub.add_parser(
        "replay", help="show a capture (.mcap) or a recording from another tool (CSV, .mat, log) in Rerun"
    )
    replay.add_argument(
        "file",
        type=Path,
        metavar="FILE",
        help="a capture written by footnav live/demo, or a PyShoe .mat, x-io CSV, OpenShoe log, CSV or a unit's "
        "raw log",
    )
    replay.add_argument("--speed", type=_pace, default=math.inf, metavar="1x|Nx|max", help="replay pace (default max)")
    replay.add_argument("--start", type=_seconds, default=0.0, metavar="S", help="start S seconds into the capture")
    replay.add_argument("--end", type=_seconds, default=math.inf, metavar="S", help="stop S seconds into the capture")
    replay.add_argument(
        "--without-tof",
        action="store_true",
        help="leave the ToF readings out (the inertial-only result of the same recording)",
    )
    _add_config_args(replay)
    _add_step_smoothing_arg(replay)
    _add_stance_arg(replay, default=None)
    _add_feet_coupling_args(replay, default="as the captured session was")
    recording = replay.add_argument_group("recordings from other tools")
    recording.add_argument(
        "--format", choices=RECORDING_FORMATS, help="recording format (default: detected from the file)"
    )
    recording.add_argument("--columns", metavar="SPEC", help="for a generic CSV: as for export")
    recording.add_argument(
        "--smooth", action="store_true", help="the RTS-smoothed track of the whole recording instead of the causal one"
    )
    _add_levels_arg(recording)
    _add_output_args(replay, capture=False)


def _add_export_command(sub: Commands) -> None:
    export = sub.add_parser("export", help="navigate a recording and write one CSV row per sample")
    export.add_argument(
        "input",
        type=Path,
        nargs="*",
        metavar="INPUT",
        help="a PyShoe .mat, x-io CSV, OpenShoe log, CSV, a unit's raw log, or a footnav capture; or folders of "
        "them, or several (or --left and --right)",
    )
    export.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        metavar="TRACK.csv",
        help="where to write (TRACK.parquet: Parquet); for a folder or several inputs, the folder to write each "
        "<name>.csv (or .parquet) in, below the subfolders it had",
    )
    export.add_argument(
        "--steps",
        type=Path,
        metavar="STEPS.csv",
        help="also write one row per step: displacement, heading change and their covariance (OpenShoe's "
        "stepwise output), length, duration, clearance",
    )
    export.add_argument(
        "--gait",
        type=Path,
        metavar="GAIT.csv",
        help="also write one row per stride of the gait parameters (length, duration, cadence, speed, stance and "
        "swing, turning, lateral deviation, clearance) and print their mean, SD and CV",
    )
    export.add_argument(
        "--output-format",
        choices=("csv", "parquet"),
        help="the track's file format (default: parquet for an output named .parquet, else csv; for a folder, "
        "csv); Parquet needs footnav[parquet]",
    )
    _add_recording_args(export)
    _add_jobs_arg(export)
    feet = _add_feet_coupling_args(export, default="coupled; to TRACK-left.csv, TRACK-right.csv in each foot's frame")
    feet.add_argument("--left", type=Path, metavar="FILE", help="the left foot's recording (with --right)")
    feet.add_argument("--right", type=Path, metavar="FILE", help="the right foot's recording (with --left)")


def _add_jobs_arg(parser: argparse.ArgumentParser) -> None:
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--jobs",
        type=_positive_int,
        metavar="N",
        help="for a folder or several files: how many run at once, one process each (default: one per core)",
    )
    where.add_argument(
        "--scheduler",
        metavar="tcp://HOST:PORT",
        help="for a folder or several files: run them on the workers of this Dask scheduler instead (needs "
        "footnav[dask]; the workers must see the files, and export's output folder, at the same paths)",
    )


def _positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected 1 or more, got {n}")
    return n


def _add_evaluate_command(sub: Commands) -> None:
    evaluate = sub.add_parser("evaluate", help="accuracy on recordings with ground truth or a closed loop")
    evaluate.add_argument("paths", type=Path, nargs="*", metavar="PATH", help="recordings, or folders of them")
    _add_recording_args(evaluate)
    feet = evaluate.add_argument_group("two feet", "a left and a right recording on one clock, navigated together")
    feet.add_argument("--left", type=Path, metavar="FILE", help="the left foot's recording (with --right)")
    feet.add_argument("--right", type=Path, metavar="FILE", help="the right foot's recording (with --left)")
    feet.add_argument(
        "--independent-feet",
        action="store_true",
        help="navigate the two feet independently only (default: coupled by the inter-foot distance bound and "
        "relative heading, and independently for comparison)",
    )
    feet.add_argument(
        "--distance-only",
        action="store_true",
        help="couple the feet by the inter-foot distance bound alone (default: and by their relative heading in "
        "stance, when it is off by more than its band)",
    )
    _add_couple_heading_arg(feet)
    _add_jobs_arg(evaluate)


def _add_experiment_command(sub: Commands) -> None:
    # the experiments' own options are parsed by run_experiment, which imports their modules
    experiment = sub.add_parser(
        "experiment", add_help=False, help="run a reproducible emulator experiment and print its table"
    )
    experiment.set_defaults(experiment_argv=[])


def _add_config_command(sub: Commands) -> None:
    config = sub.add_parser("config", help="show the effective configuration and where each value came from")
    _add_config_args(config)
    config.add_argument("--rate-divider", type=int, default=None, choices=range(15), metavar="K")
    config.add_argument("--sessions", type=Path, metavar="DIR", help="capture folder")
    config.add_argument("--no-capture", action="store_true", help="as the live option")


def _add_recording_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--format", choices=RECORDING_FORMATS, help="recording format (default: detected from the file)"
    )
    parser.add_argument(
        "--columns",
        metavar="SPEC",
        help="for a generic CSV: time=COL[:s|ms|us|ns],acc=X;Y;Z[:m/s2|g|mg],gyr=X;Y;Z[:rad/s|mrad/s|deg/s],"
        "gt=X;Y;Z,profile=NAME",
    )
    parser.add_argument("--profile", choices=PROFILES, help="unit profile (default: the format's sensor)")
    _add_smooth_arg(parser)
    _add_levels_arg(parser)


def _add_smooth_arg(parser: argparse.ArgumentParser) -> None:
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--smooth",
        action="store_const",
        const="whole",
        help="the RTS-smoothed solution of the whole recording instead of the causal filter's",
    )
    group.add_argument(
        "--step-smoothing",
        dest="smooth",
        action="store_const",
        const="step",
        help="each step smoothed once it has ended, as a --step-smoothing session shows it",
    )


def _add_levels_arg(parser: Options) -> None:
    parser.add_argument(
        "--no-stance-levels",
        dest="stance_levels",
        action="store_false",
        help="zero-velocity aiding alone: no stance height levels",
    )
