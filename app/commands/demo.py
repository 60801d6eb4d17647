"""``footnav demo``: the emulated shoe on a pseudo-terminal, through the real serial path, end to end.

emulator (gait model + IMU errors) -> pty -> device layer -> pipeline -> Rerun, then a summary with
the distance walked and the final position error against the emulator's ground truth.

``--miscalibrated``: the shoe is the emulated miscalibrated unit of ``footnav calibrate --demo`` (same
MCU id, scale factors, misalignment, biases and temperature terms, warming up during the walk); its
calibration file, if ``calibrate --demo`` made one, is applied as for any unit that connects.
With ``dual_imu`` the shoe carries a dual-IMU board: two IMUs a lever arm apart on one PCB
(:mod:`footnav.device.emulator.sensors.dual_imu`), streamed as raw multi-IMU output 0x28 with IMU mask 0b11 and
navigated by footnav's dual-IMU filter (:mod:`footnav.pipeline.dual_imu.navigator`); the summary adds what went
wrong with either IMU and whether the configured lever arm agrees with the data.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from footnav.app import heap
from footnav.app.choices import PATHS
from footnav.app.config import CLI, DEFAULT, Config, defaults
from footnav.app.feet import (
    FOOT_START_OFFSET_M,
    FootRun,
    attach_unit,
    calibration_lookup,
    check_lsl,
    close_lsl_outlets,
    dual_view_sink,
    finish_capture,
    foot_run,
    foot_sinks,
    link_reporter,
    new_session_id,
    notice,
    open_capture,
    open_lsl_outlets,
    rate_reporter,
    run_feet,
    unit_header,
)
from footnav.app.session import UnitAddress, run_device_session
from footnav.app.status import StatusLine, input_handling, lead_in_note
from footnav.app.stream import SerialSessionResult
from footnav.device.emulator.motion.floors import floor_of
from footnav.device.emulator.motion.gait import SPEED_RANGE_MPS, GaitTruth, simulate_walk, two_feet_walks
from footnav.device.emulator.scripts import BaroScript, TofScript, baro_from_height
from footnav.device.emulator.sensors.dual_imu import DEFAULT_LEVER_B_M, rigid_board
from footnav.device.emulator.sensors.icosahedron import MISCALIBRATED_MCU_ID, miscalibrated_signals, warm_up_c
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.device.emulator.sensors.tof import TofMount, TofSensorModel, tof_readings
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.modes import RawImuMode
from footnav.device.protocol.raw_imu import DUAL_IMU_MASK
from footnav.pipeline.aiding.tof_types import TofConfig
from footnav.pipeline.dual_imu.lever_arm import check_lever_arm
from footnav.pipeline.dual_imu.navigator import DualNavigator
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.navigation.navigator import Navigator
from footnav.pipeline.navigation.profiles import get_profile
from footnav.pipeline.runner import NavSink
from footnav.pipeline.two_feet.live import LOCKSTEP_MAX_LEAD_S, lockstep_for
from footnav.views.lsl import LslRequest, lsl_feet
from footnav.views.outputs import open_session_views
from numpy.typing import NDArray

DEMO_PUT_TIMEOUT_S = 60.0
"""At a pace other than real time, how long a batch may wait for room in a Rerun logger's queue."""
# the profile the filter assumes for each emulated sensor grade
PROFILE_OF_GRADE = {
    "mpu6500x4": "mpu6500x4",
    "adis16367": "adis16367",
    "icm20948": "generic",
    "icm20948-board": "generic",
    "gx3": "gx3",
    "ideal": "mpu6500x4",
}


@dataclass(frozen=True)
class DemoOptions:
    """What ``footnav demo`` was asked for."""

    path: str = "rectangle"
    duration_s: float = 60.0
    speed_mps: float = 1.4
    grade: str = "mpu6500x4"
    axes: str = "none"
    """Scale-factor and cross-axis errors of the emulated IMU(s) (a key of ``AXIS_ERRORS``)."""
    save: Path | None = None
    viewer: bool = True
    realtime: float = 1.0  # emulator pace: 1 = real time, math.inf = as fast as possible
    seed: int = 1
    feet: int = 1
    """1: one emulated shoe (``foot``); 2: ``left`` and ``right``, the same walk side by side."""
    web: bool = False
    keep_web: bool = False
    capture: bool = True
    config: Config | None = None
    """Sessions folder, filter and detector settings (default: built-in; the profile follows the grade)."""
    collect: Callable[[str], NavSink] | None = None
    """Tests: an extra NavSink per foot (given the foot name)."""
    miscalibrated: bool = False
    """The shoe is the emulated miscalibrated unit (see the module docstring)."""
    dual_imu: bool = False
    """A dual-IMU board instead of the single (calibrated-output) IMU; one foot only."""
    lever_b_m: tuple[float, float, float] | None = None
    """The lever arm the filter is told (IMU 2 in IMU 1's axes, m); None: the default board's."""
    board_lever_b_m: tuple[float, float, float] | None = None
    """Where the emulated board really has IMU 2, m; None: ``lever_b_m`` (a different one is a
    board mounted differently: the lever-arm check reports it)."""
    stance: str = "inertial"
    """Stance detector mode with ToF units: inertial, height, and, or (``footnav.pipeline.stance.height_detector``)."""
    tof: bool = False
    """Emulate the multi-sensor unit: three ToF sensors and a barometer (extension states 0xE1/0xE2),
    fused by the navigator (``footnav.pipeline.aiding.tof``)."""
    unit: str | None = None
    """Emulate this unit model (``footnav.device.models``) and run ``footnav live`` on it
    (:mod:`footnav.app.commands.demo_unit`); one foot."""
    mode: str = "auto"
    """With ``unit``: the output ``live --mode`` asks for (its rate divider is ``unit.rate_divider``)."""
    imu_mask: int | None = None
    """With ``unit`` and ``mode`` raw: the IMUs streamed and averaged (None: all of the unit's)."""
    lsl: LslRequest | None = None
    """``--lsl``: the estimates on Lab Streaming Layer too (:mod:`footnav.views.lsl`), as from a unit
    named ``emulator``."""
    feet_coupling: str = "distance+heading"
    """Two feet: coupled by the distance bound, with the relative heading too, or independent
    (``footnav.pipeline.two_feet.live.FEET_COUPLINGS``)."""
    initial_still_s: float = 3.0
    """Tests: how long one emulated foot stands before its first stride, s (0: it starts in motion,
    and its lead-in is filled in once it stands still: ``footnav.pipeline.navigation.lead_in``; the
    summary's position error is then against a truth whose origin is not the track's)."""


@dataclass(frozen=True)
class DemoSummary:
    """The figures the demo prints at the end.

    Attributes
    ----------
    distance_m
        the distance the emulated foot had walked at the last sample navigated, m (the whole walk's
        unless the demo was interrupted).
    final_error_m
        the position error at that sample, m.
    interrupted
        the demo was stopped before the end of the walk (the figures are up to where it stopped).
    """

    distance_m: float
    final_error_m: float
    samples_expected: int
    samples_navigated: int
    lost_packets: int
    interrupted: bool = False

    @property
    def error_percent(self) -> float:
        return 100.0 * self.final_error_m / self.distance_m if self.distance_m > 0 else math.nan

    def lines(self) -> list[str]:
        return [
            f"samples navigated: {self.samples_navigated} of {self.samples_expected} "
            f"(lost packets: {self.lost_packets})",
            f"distance walked:   {self.distance_m:.2f} m (ground truth"
            + (", up to the last sample navigated)" if self.interrupted else ")"),
            f"{'position error there' if self.interrupted else 'final position error'}: {self.final_error_m:.3f} m "
            + (f"= {self.error_percent:.2f} % of distance" if self.distance_m > 0 else "(no distance walked yet)"),
        ]


def distance_walked_m(truth: GaitTruth, last_index: int) -> float:
    """How far the emulated foot has walked at sample ``last_index``: foothold to foothold (as
    ``GaitTruth.distance_m`` counts the whole walk), and mid-swing the straight line from the last
    foothold to where the foot is."""
    pos = truth.pos_n_m[: last_index + 1]
    still = truth.stance[: last_index + 1]
    if pos.shape[0] == 0:
        return 0.0
    footholds = np.flatnonzero(still & ~np.concatenate([[False], still[:-1]]))  # the first sample of each stance
    points = pos[footholds] if footholds.size else pos[:1]
    if not still[-1]:
        points = np.vstack([points, pos[-1:]])
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


def summarise(
    truth: GaitTruth, result: SerialSessionResult, samples_navigated: int, *, interrupted: bool = False
) -> DemoSummary | None:
    """Compare the last estimate with the ground truth of the same sample (matched by packet counter),
    over the distance walked up to that sample."""
    nav = result.last_nav
    if nav is None or result.first_counter is None or result.link is None:
        return None
    # counters run one per sample at the 1 kHz base rate; the demo streams every sample
    last_index = min(round(float(nav.t_s[-1]) * truth.rate_hz), truth.t_s.size - 1)
    error = float(np.linalg.norm(nav.pos_n_m[-1] - truth.pos_n_m[last_index]))
    return DemoSummary(
        distance_walked_m(truth, last_index),
        error,
        truth.t_s.size,
        samples_navigated,
        result.link.lost_packets,
        interrupted=interrupted,
    )


def demo_truth(
    opts: DemoOptions, foot_index: int, walk: GaitTruth | None = None
) -> tuple[GaitTruth, NDArray[np.float64], NDArray[np.float64]]:
    """Ground truth and corrupted IMU signals of one emulated foot; with two feet, foot 0 is the left
    and foot 1 the right of one walker (``two_feet_walks``: either side of the line, half a stride
    apart, each its own strides and sensor errors)."""
    if walk is not None:
        truth = walk
    elif opts.feet == 2:
        truth = two_feet_walks(opts.path, opts.duration_s, speed_mps=opts.speed_mps, seed=opts.seed)[foot_index]
    else:
        truth = simulate_walk(
            opts.path,
            opts.duration_s,
            rate_hz=1000.0,
            speed_mps=opts.speed_mps,
            seed=opts.seed,
            initial_still_s=opts.initial_still_s,
        )
    if opts.miscalibrated:
        temp = warm_up_c(truth.t_s, start_c=32.0, end_c=42.0, time_constant_s=120.0)
        acc, gyr = miscalibrated_signals(
            truth.acc_b_mps2, truth.gyr_b_radps, temp, truth.rate_hz, grade=opts.grade, seed=opts.seed + foot_index
        )
        return truth, acc, gyr
    acc, gyr, _ = corrupt(
        truth.acc_b_mps2,
        truth.gyr_b_radps,
        truth.rate_hz,
        IMU_GRADES[opts.grade],
        seed=opts.seed + foot_index,
        axes=opts.axes,
    )
    return truth, acc, gyr


def dual_demo_truth(opts: DemoOptions) -> tuple[GaitTruth, NDArray[np.float64], NDArray[np.float64]]:
    """Ground truth of IMU 1 and the (n, 2, 3) measurements of a dual-IMU board on the foot (the two
    IMUs' errors drawn independently)."""
    truth = simulate_walk(opts.path, opts.duration_s, rate_hz=1000.0, speed_mps=opts.speed_mps, seed=opts.seed)
    board = rigid_board(truth, opts.board_lever_b_m or opts.lever_b_m or DEFAULT_LEVER_B_M)
    acc = np.empty_like(board.acc_b_mps2)
    gyr = np.empty_like(board.gyr_b_radps)
    for i in range(2):
        acc[:, i], gyr[:, i], _ = corrupt(
            board.acc_b_mps2[:, i],
            board.gyr_b_radps[:, i],
            truth.rate_hz,
            IMU_GRADES[opts.grade],
            seed=opts.seed + i,
            axes=opts.axes,
        )
    return truth, acc, gyr


def demo_extensions(
    opts: DemoOptions, truth: GaitTruth, foot_index: int, mounting: TofConfig | None = None
) -> tuple[TofScript | None, BaroScript | None]:
    """The ToF and barometer readings of one emulated foot (none unless ``opts.tof``), its sensors
    mounted as ``mounting`` says (the [tof] configuration; default: ``TofConfig()``)."""
    if not opts.tof:
        return None, None
    m = mounting or TofConfig()
    dirs = np.asarray(m.dir_b) / np.linalg.norm(m.dir_b, axis=1, keepdims=True)
    mounts = tuple(TofMount(lever, (d[0], d[1], d[2])) for lever, d in zip(m.lever_b_m, dirs.tolist(), strict=True))
    sensors = TofSensorModel(mounts=mounts, sigma_m=m.sigma_range_m, seed=opts.seed + foot_index)
    tof = tof_readings(truth.t_s, truth.pos_n_m, truth.quat_nb_wxyz, floor_of(opts.path), sensors)
    return tof, baro_from_height(truth.t_s, truth.pos_n_m[:, 2])


def check_options(opts: DemoOptions) -> None:
    """Refuse combinations the emulator cannot serve, before anything starts.

    Raises
    ------
    FootnavError
        an unknown path, a number of feet other than 1 or 2, a dual-IMU board on two feet, axis
        errors on the miscalibrated unit, or a walking speed the gait model does not cover.
    """
    if opts.path not in PATHS:
        raise FootnavError(f"unknown path {opts.path!r}; choose one of {', '.join(PATHS)}")
    if opts.feet not in (1, 2):
        raise FootnavError(f"the demo emulates 1 or 2 feet, not {opts.feet}")
    if opts.dual_imu and opts.feet != 1:
        raise FootnavError("the dual-IMU demo emulates one shoe: drop --feet 2 or --dual-imu")
    if opts.miscalibrated and opts.axes != "none":
        raise FootnavError("the miscalibrated unit has its own scale and misalignment errors; drop --axis-errors")
    if opts.unit is not None and (opts.feet != 1 or opts.dual_imu or opts.tof or opts.miscalibrated):
        raise FootnavError("--unit emulates one unit of that model: drop --feet 2, --dual-imu, --tof, --miscalibrated")
    if opts.unit is None and (opts.mode != "auto" or opts.imu_mask is not None or _rate_divider_given(opts)):
        raise FootnavError("--mode, --rate-divider and --imu-mask need --unit MODEL (the unit they ask)")
    if opts.imu_mask is not None and opts.mode != "raw":
        raise FootnavError("--imu-mask applies to --mode raw (the IMUs to stream and average)")
    lo, hi = SPEED_RANGE_MPS
    if not lo <= opts.speed_mps <= hi:
        raise FootnavError(f"walking speed {opts.speed_mps:g} m/s: the emulated gait covers {lo} to {hi} m/s")


def _rate_divider_given(opts: DemoOptions) -> bool:
    return opts.config is not None and opts.config.source("unit.rate_divider") == CLI


def emulated_servers(
    opts: DemoOptions, truths: list[tuple[GaitTruth, NDArray[np.float64], NDArray[np.float64]]], cfg: Config
) -> list[PtyShoeServer]:
    """One pseudo-terminal shoe per foot, serving its corrupted signals (and ToF and barometer with ``tof``)."""
    if opts.dual_imu:
        t_dual, acc_dual, gyr_dual = truths[0]
        return [
            PtyShoeServer(
                t_dual.t_s,
                acc_dual[:, 0],
                gyr_dual[:, 0],
                speed=opts.realtime,
                record=False,
                imu_acc_b_mps2=acc_dual,
                imu_gyr_b_radps=gyr_dual,
            )
        ]
    mcu_id = MISCALIBRATED_MCU_ID if opts.miscalibrated else None
    ext = [demo_extensions(opts, t, k, cfg.tof_config(opts.stance)) for k, (t, _, _) in enumerate(truths)]
    return [
        PtyShoeServer(t.t_s, acc, gyr, speed=opts.realtime, record=False, mcu_id=mcu_id, tof=tof, baro=baro)
        for (t, acc, gyr), (tof, baro) in zip(truths, ext, strict=True)
    ]


def run_demo(opts: DemoOptions) -> int:
    """Run the demo; returns the process exit code."""
    check_options(opts)
    return _shoe_demo(opts) if opts.unit is None else _unit_demo(opts)


def _shoe_demo(opts: DemoOptions) -> int:
    """The emulated shoe(s) through the session code of ``demo`` (see the module docstring)."""
    feet = ("foot",) if opts.feet == 1 else ("left", "right")
    walks = (
        two_feet_walks(opts.path, opts.duration_s, speed_mps=opts.speed_mps, seed=opts.seed) if opts.feet == 2 else ()
    )
    truths = (
        [dual_demo_truth(opts)]
        if opts.dual_imu
        else [demo_truth(opts, k, walks[k] if walks else None) for k in range(len(feet))]
    )
    truth = truths[0][0]
    board = " with a dual-IMU board" if opts.dual_imu else ""
    axes = "" if opts.axes == "none" else f", axis errors {opts.axes}"
    print(
        f"footnav demo: {len(feet)} emulated shoe(s){board} ({opts.grade}{axes}), {opts.path} walk, "
        f"{opts.duration_s:.0f} s at {opts.speed_mps:.1f} m/s, 1 kHz over a pseudo-terminal",
        file=sys.stderr,
    )
    cfg = demo_config(opts)
    session_id = new_session_id("demo")
    lsl_streams = lsl_feet(
        opts.lsl,
        dict.fromkeys(feet, "emulator"),
        units=f"footnav emulator ({opts.grade})",
        rates=dict.fromkeys(feet, truth.rate_hz),
    )
    check_lsl(lsl_streams)  # pylsl missing: stop before the viewer and the capture start
    heap.limit_arenas()  # before the viewer's and the capture's threads start
    views, notes = open_session_views(
        save=opts.save,
        want_viewer=opts.viewer,
        web=opts.web,
        keep_web=opts.keep_web,
        feet=feet,
        recording_id=session_id,
        notice=notice,
        dual_runs=feet if opts.dual_imu else (),
    )
    for note in notes:
        print(note, file=sys.stderr)
    two = len(feet) > 1
    if views is not None:
        for foot, (t, _, _) in zip(feet, truths, strict=True):
            offset = np.asarray(FOOT_START_OFFSET_M[foot]) if two else np.zeros(3)
            views.log_truth(t.pos_n_m + offset, t_s=t.t_s, foot=foot)
        views.log_event(
            f"demo: {opts.path}, {opts.duration_s:.0f} s, grade {opts.grade}, feet {', '.join(feet)}", t_s=0.0
        )
    servers = emulated_servers(opts, truths, cfg)
    extra = {"command": "footnav demo", "emulator": f"{opts.path} {opts.grade} axes {opts.axes}"}
    extra["feet_coupling"] = opts.feet_coupling  # a two-feet replay couples the feet as the demo did
    capture = open_capture(cfg, session_id, enabled=opts.capture, extra=extra)
    status = StatusLine(feet=feet)
    nav_config = cfg.nav_config()
    lever = opts.lever_b_m or DEFAULT_LEVER_B_M
    tof = cfg.tof_config(opts.stance)
    runs = [
        foot_run(foot, server.port, nav_config, truth.rate_hz, tof=tof, dual_lever_b_m=lever if opts.dual_imu else None)
        for foot, server in zip(feet, servers, strict=True)
    ]
    # Faster than real time the emulator waits for footnav, so footnav waits for the Rerun loggers
    # (as a replay does) rather than dropping samples from the recording.
    put_timeout_s = 0.0 if opts.realtime == 1.0 else DEMO_PUT_TIMEOUT_S
    for run in runs:
        foot_sinks(run, views, status, two_feet=two, put_timeout_s=put_timeout_s)
        if opts.collect is not None:
            run.add_collector(opts.collect(run.foot))
        if views is not None and isinstance(run.navigator, DualNavigator):
            run.sinks.append(dual_view_sink(run.navigator, views, run.foot))
        if capture is not None:
            run.tap = capture.add_unit(
                unit_header(
                    run.foot,
                    run.port,
                    "pty (emulator)",
                    cfg,
                    0,
                    extensions=opts.tof,
                    stance=opts.stance,
                    dual_imu_lever_b_m=lever if opts.dual_imu else None,
                )
            )
    server_of = dict(zip(feet, servers, strict=True))
    lockstep = lockstep_for(
        {run.foot: run.navigator for run in runs},
        opts.feet_coupling,
        max_lead_s=LOCKSTEP_MAX_LEAD_S if opts.realtime == 1.0 else None,  # faster: the emulator waits
        log_event=getattr(views, "log_event", None),
        notice=notice,
    )

    async def session(run: FootRun) -> None:
        server = server_of[run.foot]
        await run_device_session(
            UnitAddress("serial", server.port),
            run.navigator if lockstep is None else lockstep.port_for(run.foot),
            run.pipeline_sinks(),
            lead_in=run.lead_in_sink(),
            expect_samples=truth.t_s.size,
            source_done=server.finished.is_set,
            status=status.foot(run.foot),
            result=run.result,
            capture=run.tap,
            on_open=lambda unit: attach_unit(run, unit),
            on_link_event=link_reporter(run, views, capture, two_feet=two),
            calibration=None if opts.dual_imu else calibration_lookup(cfg, run.foot, capture, views, two_feet=two),
            mode=RawImuMode(imu_mask=DUAL_IMU_MASK) if opts.dual_imu else None,
            extensions=opts.tof and not opts.dual_imu,
            on_rate=rate_reporter(run, views, two_feet=two),
        )

    interrupted = False
    lsl = None
    try:
        lsl = open_lsl_outlets(lsl_streams, runs, wait_s=opts.lsl.wait_s if opts.lsl else 0.0)
        with contextlib.ExitStack() as stack:
            for server in servers:
                stack.enter_context(server)
            asyncio.run(run_feet(runs, session, lockstep))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        status.finish()
        finish_capture(capture, runs)
        if views is not None:
            for note in views.close():
                notice(note)
        close_lsl_outlets(lsl)
    if interrupted:
        print("interrupted: stopped the unit and closed the recording", file=sys.stderr)
    code = print_summaries(opts, runs, truths, lever, interrupted=interrupted)
    return 130 if interrupted else code


def print_summaries(
    opts: DemoOptions,
    runs: list[FootRun],
    truths: list[tuple[GaitTruth, NDArray[np.float64], NDArray[np.float64]]],
    lever: tuple[float, float, float],
    *,
    interrupted: bool = False,
) -> int:
    """Each foot's summary against the ground truth (up to where it stopped, if ``interrupted``); 1 if
    a foot never navigated, else 0."""
    two = len(runs) > 1
    code = 0
    for run, (t, _, _) in zip(runs, truths, strict=True):
        summary = summarise(t, run.result, run.navigator.stats.samples_out, interrupted=interrupted)
        prefix = f"{run.foot}: " if two else ""
        if summary is None:
            print(f"{prefix}no navigation output (the unit never stood still long enough to align)", file=sys.stderr)
            code = 1
            continue
        for line in summary.lines():
            print(prefix + line)
        if handled := input_handling(run.navigator.stats):
            print(f"{prefix}input handling: {handled}")
        if note := lead_in_note(run.navigator.stats):
            print(f"{prefix}lead-in: {note.removeprefix(', ')}")
        if isinstance(run.navigator, DualNavigator):
            for line in dual_summary_lines(run.navigator, truths[0][1], truths[0][2], lever):
                print(prefix + line)
        if opts.tof and isinstance(run.navigator, Navigator):
            counts = run.navigator.tof.counts.by_reason
            listed = ", ".join(f"{k} {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1]))
            print(f"{prefix}ToF readings: {listed or 'none received'}")
    return code


def dual_summary_lines(
    navigator: DualNavigator,
    acc_b_mps2: NDArray[np.float64],
    gyr_b_radps: NDArray[np.float64],
    lever: tuple[float, float, float],
) -> list[str]:
    """What the dual-IMU demo adds: faults of either IMU, and the lever-arm check on what was sent."""
    lines = [f"dual-IMU: {m}" for m in navigator.messages] or ["dual-IMU: both IMUs usable at every sample"]
    _, _, stance = DualNavigator(navigator.config, navigator.rate_hz).detector.update(
        np.nan_to_num(acc_b_mps2[:, 0]), np.nan_to_num(gyr_b_radps[:, 0])
    )
    sigma = get_profile(navigator.config.filter.profile.name).acc_noise_mps2_rthz * math.sqrt(navigator.rate_hz)
    check = check_lever_arm(acc_b_mps2, gyr_b_radps, stance, np.asarray(lever), navigator.rate_hz, sigma_acc_mps2=sigma)
    lines.append(f"dual-IMU: {check.message}")
    return lines


def demo_config(opts: DemoOptions) -> Config:
    """The session's configuration: the one given, or the built-in one; the unit profile follows the
    emulated sensor grade unless the configuration names one."""
    cfg = opts.config if opts.config is not None else defaults()
    if opts.config is None or cfg.source("unit.profile") == DEFAULT:
        cfg.set("unit.profile", PROFILE_OF_GRADE[opts.grade], f"demo (grade {opts.grade})")
    return cfg


def _unit_demo(opts: DemoOptions) -> int:
    """``demo --unit``: ``footnav live`` against the emulated unit of that model."""
    from footnav.app.commands.demo_unit import run_unit_demo
    from footnav.app.commands.live import LiveOptions

    cfg = demo_config(opts)

    lsl = None if opts.lsl is None else dataclasses.replace(opts.lsl, identity=opts.lsl.identity or "emulator")

    def live(port: str) -> LiveOptions:
        return LiveOptions(
            ports={"foot": port},
            config=cfg,
            save=opts.save,
            viewer=opts.viewer,
            web=opts.web,
            keep_web=opts.keep_web,
            capture=opts.capture,
            lsl=lsl,
            fused_imu_mask=opts.imu_mask,
        )

    return run_unit_demo(
        model=opts.unit or "",
        output=opts.mode,
        path=opts.path,
        duration_s=opts.duration_s,
        speed_mps=opts.speed_mps,
        grade=opts.grade,
        seed=opts.seed,
        pace=opts.realtime,
        live=live,
        collect=opts.collect,
    )
