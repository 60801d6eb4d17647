"""``footnav replay FILE``: a logged session through the same device decoding and pipeline as live.

footnav captures (``.mcap``): each unit's captured device -> host reads are fed, one captured read per
``read()``, to the same :class:`footnav.device.unit.OpenShoeUnit` (start handshake included: the unit's ACKs
are in the capture), with the navigator settings recorded in the capture, and batches carry the
captured host times: the estimates equal the live ones exactly. A replay stops where the live session
stopped (the capture's ``end`` event), or at the end of a truncated capture.

Recordings from other tools are dispatched by file type in :func:`detect_format`; their loaders are
not part of this version, so they get a clear "unsupported format" message.
"""

from __future__ import annotations

import asyncio
import io
import math
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from footnav.app.calibration_store import StoredCalibration, calibration_dir, load_calibration, stored_calibration
from footnav.app.config import Config, apply_capture_settings
from footnav.app.feet import (
    ONBOARD_INS_STATES,
    ONBOARD_TITLES,
    FootRun,
    check_lsl,
    close_lsl_outlets,
    dual_view_sink,
    foot_run,
    foot_sinks,
    notice,
    open_lsl_outlets,
    rate_reporter,
    run_feet,
)
from footnav.app.session import CalibrationLookup, run_unit_session, unit_mode
from footnav.app.status import Progress, StatusLine, input_handling, lead_in_note
from footnav.device.files.capture import EXPECTED, CaptureSummary, summarize_capture
from footnav.device.files.capture_schema import MCAP_MAGIC
from footnav.device.links.replay import CaptureReplayLink
from footnav.device.modes import Mode
from footnav.device.protocol.raw_imu import DUAL_IMU_MASK
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.calibration.model import CalibrationError
from footnav.pipeline.dual_imu.navigator import DualNavigator
from footnav.pipeline.errors import FootnavError, InputFormatError
from footnav.pipeline.runner import NavSink
from footnav.pipeline.two_feet.live import FEET_COUPLINGS, lockstep_for
from footnav.views.lsl import LslRequest, lsl_feet
from footnav.views.outputs import open_session_views

FULL_SPEED_JOIN_SAMPLES = 5000
"""A replay at full speed passes the IMU samples on in batches of about this many (a captured read
holds about 30 at 1 kHz): the same estimates, a fraction of the per-batch cost."""
REPLAY_PUT_TIMEOUT_S = 60.0
"""Faster than real time, the pipeline waits for the Rerun loggers rather than dropping samples."""


def detect_format(path: Path) -> str:
    """``footnav-capture`` for our MCAP captures; otherwise raise with what was expected.

    Raises
    ------
    InputFormatError
        missing file, or not a footnav capture (other tools' recordings included).
    """
    if not path.exists():
        raise InputFormatError(f"no such file: {path}")
    if path.is_dir():
        raise InputFormatError(f"{path} is a folder; expected {EXPECTED}")
    with open(path, "rb") as f:
        head = f.read(8)
    if head == MCAP_MAGIC:
        return "footnav-capture"
    if not head:
        raise InputFormatError(f"{path} is an empty file; expected {EXPECTED}")
    kinds = {
        ".mcap": "not an MCAP file (no MCAP magic bytes)",
        ".mat": "a MATLAB file",
        ".csv": "a CSV file",
        ".txt": "a text file",
        ".rrd": "a Rerun recording",
    }
    what = kinds.get(path.suffix.lower(), "a file of unknown type")
    raise InputFormatError(f"unsupported format: {path} is {what}; expected {EXPECTED}")


@dataclass(frozen=True)
class ReplayOptions:
    """What ``footnav replay`` was asked for.

    Attributes
    ----------
    speed
        1.0 = as captured, N = N times faster, ``math.inf`` = as fast as possible.
    start_s, end_s
        window in session seconds (device time since the first sample, the
        recording's ``imu_time``), exact to the sample.
    collect
        an extra NavSink per foot (``export`` of a capture, tests).
    quiet
        a step of another command (``export``): no start line or output notes, progress only on a terminal.
    tof
        pass the unit's ToF readings to the navigator (False: the same capture navigated
        inertial-only, to measure what the ToF sensors add).
    stance
        stance detector mode with ToF units (None: as recorded in the capture).
    lsl
        ``--lsl``: the estimates on Lab Streaming Layer too (:mod:`footnav.views.lsl`), each foot
        as from a unit ``replay:<its captured port>``.
    feet_coupling
        two feet: as the capture's session did (None: its ``feet_coupling``, coupled by the distance
        bound in captures that do not say), or ``footnav.pipeline.two_feet.live.FEET_COUPLINGS``.
    """

    path: Path
    config: Config
    speed: float = math.inf
    start_s: float = 0.0
    end_s: float = math.inf
    save: Path | None = None
    viewer: bool = True
    web: bool = False
    keep_web: bool = False
    config_is_explicit: bool = False
    collect: Callable[[str], NavSink] | None = None
    tof: bool = True
    stance: str | None = None
    lsl: LslRequest | None = None
    feet_coupling: str | None = None
    quiet: bool = False


def checked_summary(opts: ReplayOptions) -> CaptureSummary:
    """The capture's summary, once it is known to hold a navigation session to replay.

    Raises
    ------
    InputFormatError
        the file is not a footnav capture, declares no unit, holds no data, or is a calibration.
    FootnavError
        ``feet_coupling`` is given for a capture of one foot.
    """
    detect_format(opts.path)
    summary = summarize_capture(opts.path)
    info = summary.info
    if not info.units:
        raise InputFormatError(f"{opts.path} declares no unit; expected {EXPECTED}")
    if not any(summary.rx_bytes.values()):
        cut = "ends before its first complete chunk of data" if summary.truncated else "holds no data from a unit"
        raise InputFormatError(f"{opts.path} {cut}; nothing to replay")
    if any(u.settings.get("mode") == "calibration_raw_imu" for u in info.units):
        raise InputFormatError(
            f"{opts.path} is a calibration procedure (raw IMU output); refit it with "
            f"`footnav calibrate --capture {opts.path}`"
        )
    if opts.feet_coupling is not None and len(info.units) != 2:
        raise FootnavError(f"--independent-feet and --distance-only are for two feet; {opts.path} holds one")
    for warning in info.warnings:
        notice(warning)
    if summary.gaps:
        spans = ", ".join(f"{g.start}-{g.end}" for g in summary.gaps)
        notice(
            f"{opts.path} has {len(summary.gaps)} damaged stretch(es) (bytes {spans} of {opts.path.stat().st_size} "
            "fail their CRC check): the replay skips each and resumes at the next intact chunk"
        )
    if summary.truncated:
        notice(f"{opts.path} ends mid-record (the writer was killed or the disk was full): replaying what is there")
    return summary


def window_note(opts: ReplayOptions) -> str:
    """What the replay's first line says of its window ('' for none)."""
    if not (opts.start_s > 0 or math.isfinite(opts.end_s)):
        return ""
    return (
        f", window {opts.start_s:g}-{opts.end_s:g} s (navigated from the capture's start, so that the window "
        "starts from the state it had there; shown from the window's start)"
    )


def check_window_reached(opts: ReplayOptions, runs: list[FootRun], *, interrupted: bool = False) -> None:
    """Raise ``FootnavError`` when the capture ended before the window's start (nothing was shown;
    not when the user stopped the replay)."""
    if opts.start_s <= 0 or interrupted:
        return
    ends = [float(r.result.last_nav.t_s[-1]) for r in runs if r.result.last_nav is not None]
    if not ends or max(ends) < opts.start_s:
        end = f"{max(ends):.1f} s of device time" if ends else "no sample navigated"
        raise FootnavError(f"--start {opts.start_s:g} s is after the end of the capture ({end}): nothing to show")


def onboard_outputs(summary: CaptureSummary, *, windowed: bool = False) -> dict[str, str]:
    """foot -> "ins" or "steps" for the feet whose capture holds the unit's own solution: by its
    header, or by a ``mode`` event (a unit whose firmware offered stepwise output only).

    Raises
    ------
    FootnavError
        ``windowed``, and a foot's capture is stepwise output (no device clock to window).
    """
    out = {u.foot: str(u.settings["mode"]) for u in summary.info.units if u.settings.get("mode") in ONBOARD_TITLES}
    for foot, events in summary.events.items():
        for event in events:
            if event.get("event") == "mode" and event.get("mode") in ONBOARD_TITLES:
                out[foot] = str(event["mode"])
    if windowed and "steps" in out.values():
        raise FootnavError("--start/--end need the unit's clock: a capture of stepwise output has none")
    return out


def captured_mode(settings: dict[str, Any], onboard: str | None, *, dual: bool) -> Mode | None:
    """The output mode a captured unit was started in, from its header's settings (None: the
    calibrated IMU output)."""
    fused_mask = settings.get("fused_imu_mask")
    output = onboard or ("raw" if dual or isinstance(fused_mask, int) else "imu")
    return unit_mode(
        output,
        int(settings.get("rate_divider_log2", 0)),
        int(fused_mask) if isinstance(fused_mask, int) else DUAL_IMU_MASK,
        tuple(int(i) for i in settings.get("ins_state_ids", ONBOARD_INS_STATES)),
    )


def capture_calibration_lookup(summary: CaptureSummary, cfg: Config, foot: str) -> CalibrationLookup | None:
    """The live session asked the unit its MCU id (an ``mcu_id`` event): ask again, from the capture. The
    calibration the session applied is the one the capture keeps (older captures: the file of that name)."""
    asked = [e for e in summary.events.get(foot, []) if e.get("event") == "mcu_id"]
    if not asked:
        return None
    folder = calibration_dir(cfg)
    apply = bool(cfg["calibration.apply"])
    prefix = f"{foot}: " if len(summary.info.feet) > 1 else ""
    applied, document = asked[0].get("calibration"), asked[0].get("calibration_document")

    def find(mcu_id: bytes) -> StoredCalibration | None:
        if not apply:
            return None
        if document is not None:
            return stored_calibration(Path(str(applied)), document, mcu_id)
        stored = load_calibration(folder, mcu_id)
        if stored is None and applied is not None:
            raise CalibrationError(
                f"the live session applied the calibration {applied}, which this capture does not keep and "
                f"{folder} does not hold: this replay differs from the session"
            )
        return stored

    def report(mcu_id: bytes | None, stored: StoredCalibration | None, note: str) -> None:
        if apply:
            notice(prefix + note)

    return CalibrationLookup(find=find, report=report)


def captured_coupling(session: Mapping[str, str]) -> str:
    """How the captured session navigated its two feet (``feet_coupling``; captures before it was kept:
    coupled by the distance bound, the default since)."""
    coupling = session.get("feet_coupling", "distance")
    if coupling not in FEET_COUPLINGS:
        notice(
            f"the capture's feet_coupling is {coupling!r}, not one of {', '.join(FEET_COUPLINGS)}: coupled by distance"
        )
        return "distance"
    return coupling


def _say(opts: ReplayOptions, *lines: str) -> None:
    """``lines`` on stderr, unless the replay is a step of another command (``opts.quiet``)."""
    for line in () if opts.quiet else lines:
        print(line, file=sys.stderr)


def run_replay(opts: ReplayOptions) -> int:
    """Replay a capture; returns the exit code.

    Raises
    ------
    InputFormatError
        the file is not a footnav capture.
    """
    summary = checked_summary(opts)
    info = summary.info
    cfg = opts.config
    feet = info.feet
    for unit in info.units:
        nav = unit.settings.get("nav_config")
        if isinstance(nav, dict) and not opts.config_is_explicit:
            apply_capture_settings(cfg, nav, f"capture {opts.path.name}")
        break  # one settings set for all feet (they were one session)
    rate_of = {u.foot: float(u.settings.get("rate_hz", 1000.0)) for u in info.units}
    windowed = opts.start_s > 0 or math.isfinite(opts.end_s)
    _say(
        opts,
        f"replaying {opts.path} ({', '.join(f'{u.foot}: {u.port}' for u in info.units)}; "
        f"{summary.duration_s:.1f} s captured) at "
        f"{'max speed' if math.isinf(opts.speed) else f'{opts.speed:g}x'}" + window_note(opts),
    )
    lever_of = {
        u.foot: tuple(float(v) for v in u.settings["dual_imu_lever_b_m"])
        for u in info.units
        if isinstance(u.settings.get("dual_imu_lever_b_m"), list)
    }
    onboard_of = onboard_outputs(summary, windowed=windowed)
    lsl_streams = lsl_feet(
        opts.lsl,
        {u.foot: f"replay:{u.port}" for u in info.units},
        units={u.foot: u.unit for u in info.units},
        rates={foot: 0.0 if onboard_of.get(foot) == "steps" else rate_of.get(foot, 1000.0) for foot in feet},
    )
    check_lsl(lsl_streams)  # pylsl missing: stop before the viewer starts
    views, notes = open_session_views(
        save=opts.save,
        want_viewer=opts.viewer,
        web=opts.web,
        keep_web=opts.keep_web,
        feet=feet,
        recording_id=str(info.session.get("session_id", opts.path.stem)),
        notice=notice,
        dual_runs=tuple(lever_of),
        tof=any(bool(u.settings.get("extensions", False)) for u in info.units),
    )
    _say(opts, *notes)
    realtime = opts.speed == 1.0
    status = StatusLine(feet=feet, stream=sys.stderr if realtime else io.StringIO())
    progress = (
        Progress(f"replay {opts.path.name}")
        if not realtime and (sys.stderr.isatty() or not opts.quiet)  # a step of export: on a terminal only
        else None
    )
    nav_config = cfg.nav_config()
    clock_origin: list[int] = []
    runs: list[FootRun] = []
    links: dict[str, CaptureReplayLink] = {}
    for k, foot in enumerate(feet):
        recorded = info.units[feet.index(foot)].settings.get("stance", "inertial")
        rate_hz = rate_of.get(foot, 1000.0)
        lever = lever_of.get(foot)  # a dual-IMU board: its raw two-IMU stream to the dual-IMU navigator
        run = foot_run(
            foot,
            opts.path.name,
            nav_config,
            rate_hz,
            tof=cfg.tof_config(opts.stance or str(recorded)),
            dual_lever_b_m=None if lever is None else (lever[0], lever[1], lever[2]),
            onboard=onboard_of.get(foot),
        )
        navigator = run.navigator
        foot_sinks(
            run,
            views,
            status,
            two_feet=len(feet) > 1,
            put_timeout_s=0.0 if realtime else REPLAY_PUT_TIMEOUT_S,
        )
        if views is not None and isinstance(navigator, DualNavigator):
            run.sinks.append(dual_view_sink(navigator, views, foot))
        if opts.collect is not None:
            run.add_collector(opts.collect(foot))
        links[foot] = CaptureReplayLink(
            opts.path,
            foot,
            speed=opts.speed,
            paced=opts.start_s <= 0,
            clock_origin=clock_origin,
            on_progress=progress.update if (progress is not None and k == 0) else None,
        )
        runs.append(run)
    lockstep = lockstep_for(
        {run.foot: run.navigator for run in runs},
        opts.feet_coupling or captured_coupling(info.session),
        log_event=getattr(views, "log_event", None),
        notice=notice,
    )
    ends = {
        foot: next((e.get("samples") for e in events if e.get("event") == "end"), None)
        for foot, events in summary.events.items()
    }

    async def session(run: FootRun) -> None:
        link = links[run.foot]
        unit = OpenShoeUnit(link)
        if run.health is not None:
            run.health.stats = lambda: unit.stats
        expect = ends.get(run.foot)
        settings = info.units[feet.index(run.foot)].settings
        fused_mask = settings.get("fused_imu_mask")
        onboard = onboard_of.get(run.foot)
        await run_unit_session(
            unit,
            run.navigator if lockstep is None else lockstep.port_for(run.foot),
            run.pipeline_sinks(),
            lead_in=run.lead_in_sink(),
            start=True,  # the same handshake as live: the unit's answers are in the capture
            rate_divider_log2=int(settings.get("rate_divider_log2", 0)),
            expect_samples=expect if (isinstance(expect, int) and not windowed) else None,
            status=status.foot(run.foot),
            result=run.result,
            idle_notice_s=None,
            window=(opts.start_s, opts.end_s) if windowed else None,
            on_window=lambda: setattr(link, "paced", True),
            calibration=capture_calibration_lookup(summary, cfg, run.foot) if onboard is None else None,
            extensions=bool(settings.get("extensions", False)),
            use_ranges=opts.tof,
            join_samples=FULL_SPEED_JOIN_SAMPLES if math.isinf(opts.speed) else 0,
            mode=captured_mode(settings, onboard, dual=run.foot in lever_of),
            fuse_imus=isinstance(fused_mask, int),
            on_rate=rate_reporter(run, views, two_feet=len(feet) > 1),
        )

    interrupted = False
    lsl = None
    try:
        lsl = open_lsl_outlets(lsl_streams, runs, wait_s=opts.lsl.wait_s if opts.lsl else 0.0)
        asyncio.run(run_feet(runs, session, lockstep))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if realtime:
            status.finish()
        elif progress is not None:
            progress.update(1, 1)
            progress.finish()
        if views is not None:
            for note in views.close():
                notice(note)
        close_lsl_outlets(lsl)
    if interrupted:
        print("interrupted: the recording was closed", file=sys.stderr)
    print_results(opts, summary, runs, links, status)
    check_window_reached(opts, runs, interrupted=interrupted)
    return 130 if interrupted else 0  # 130: the shell's code for Ctrl-C (SIGINT)


def damage_report(opts: ReplayOptions, summary: CaptureSummary, run: FootRun, link: CaptureReplayLink) -> list[str]:
    """What one foot's replay lost to damaged stretches of the capture: one line per stretch (its
    bytes, how long the stream went without data and from when), then the samples lost: against the
    live session's count (its ``end`` event) where the capture holds it, else by package numbers."""
    lines = []
    size = opts.path.stat().st_size
    for lost in link.lost:
        where = f"{opts.path.name}: bytes {lost.gap.start}-{lost.gap.end} of {size} are damaged and were skipped; "
        if lost.seconds is None:
            lines.append(where + "nothing of this unit comes after them")
            continue
        since = ""
        if lost.before_ns is not None and summary.first_ns is not None:
            since = f" (from {(lost.before_ns - summary.first_ns) / 1e9:.2f} s into the capture)"
        lines.append(where + f"no data for {lost.seconds:.2f} s{since}")
    if link.lost:
        ends = [e.get("samples") for e in summary.events.get(run.foot, []) if e.get("event") == "end"]
        got = run.result.samples_received
        if ends and isinstance(ends[0], int) and ends[0] >= got:
            missing = f"{ends[0] - got} samples lost ({got} of the {ends[0]} the live session navigated)"
        else:
            numbers = run.result.link.lost_packets if run.result.link is not None else 0
            missing = f"{numbers} packets lost by their package numbers"
        lines.append(f"{len(link.lost)} damaged stretch(es) skipped: {missing}")
    return lines


def print_results(
    opts: ReplayOptions,
    summary: CaptureSummary,
    runs: list[FootRun],
    links: dict[str, CaptureReplayLink],
    status: StatusLine,
) -> None:
    """Damaged stretches the replay skipped, and each foot's samples and distance."""
    for run in runs:
        for line in damage_report(opts, summary, run, links[run.foot]):
            notice((f"{run.foot}: " if len(runs) > 1 else "") + line)
    for run in runs:
        prefix = f"{run.foot}: " if len(runs) > 1 else ""
        st = run.navigator.stats
        lost = run.result.link.lost_packets if run.result.link is not None else 0
        print(
            f"{prefix}samples navigated: {st.samples_out} of {run.result.samples_received} replayed "
            f"(lost packets: {lost}); distance {status.foot(run.foot).distance_m:.2f} m"
            + (f"; {handled}" if (handled := input_handling(st)) else "")
            + lead_in_note(st).replace(", ", "; ", 1)
        )
