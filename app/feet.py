"""The feet of a session, built the same way for ``live``, ``demo`` and ``replay``.

A :class:`FootRun` is one foot: its navigator (causal, step-smoothing or dual-IMU, from the session's
configuration), its gait events (:class:`footnav.pipeline.gait.events.GaitEventTracker`, with the
session's ToF settings), its sinks (views, status line, link health) and its capture tap. Also here:
the capture file of a session, its unit headers, link reports and summaries, and running every foot
at once so that a foot whose unit fails leaves the others going.
"""

from __future__ import annotations

import asyncio
import dataclasses
import sys
import uuid
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from footnav.app import heap
from footnav.app.calibration_store import StoredCalibration, any_calibrations, calibration_dir, load_calibration
from footnav.app.config import Config
from footnav.app.session import CalibrationLookup, LinkHealth, UnitAddress
from footnav.app.status import StatusLine, input_handling, lead_in_note
from footnav.app.stream import SerialSessionResult
from footnav.device.errors import DeviceError
from footnav.device.files.capture import CaptureTap, CaptureWriter, UnitHeader
from footnav.device.links.reconnecting import LinkEvent, LinkGap, ReconnectingLink
from footnav.device.models import DEFAULT_MODEL, UnitModel
from footnav.device.onboard import OnboardInsNavigator, OnboardStepNavigator
from footnav.device.protocol.commands import STATE_IMU_TS, STATE_P, STATE_POSITION, STATE_QUATERNION, STATE_VELOCITY
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.aiding.tof_types import TofConfig
from footnav.pipeline.dual_imu.board_eskf import DualEskfConfig
from footnav.pipeline.dual_imu.navigator import DualNavConfig, DualNavigator
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.gait.events import GaitEventTracker
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavConfig, Navigator
from footnav.pipeline.runner import NavSink
from footnav.pipeline.smoothing.stepwise import StepSmoothingNavigator
from footnav.views.dual_imu import DualRunView
from footnav.views.outputs import SessionViews

if TYPE_CHECKING:
    from footnav.pipeline.two_feet.live import FeetLockstep
    from footnav.views.lsl import LslFoot, LslOutlets

FOOT_START_OFFSET_M: dict[str, tuple[float, float, float]] = {
    "left": (0.0, 0.1, 0.0),
    "right": (0.0, -0.1, 0.0),
}
"""Where each foot's navigation origin is drawn: two feet start side by side, 0.2 m apart (each
navigator starts at its own origin; this offset is for display only)."""

UNIT_KIND = "OpenShoe/MIMU/Oblu, calibrated IMU output (0x40)"
ONBOARD_TITLES = {"ins": "INS states", "steps": "stepwise dead reckoning"}
ONBOARD_INS_STATES = (STATE_IMU_TS, STATE_POSITION, STATE_VELOCITY, STATE_QUATERNION, STATE_P)
"""The INS states a session asks the unit for: time stamp, position, velocity, attitude, covariance."""


def notice(text: str) -> None:
    """A one-line notice on stderr, on a fresh line (the status line may be mid-way)."""
    print(f"\nfootnav: {text}", file=sys.stderr, flush=True)


def new_session_id(kind: str, now: datetime | None = None) -> str:
    """``<kind>-YYYYmmdd-HHMMSS-<6 hex>``: the recording id and the capture file's name."""
    return f"{kind}-{(now or datetime.now()).strftime('%Y%m%d-%H%M%S')}-{uuid.uuid4().hex[:6]}"


def offset_sink(sink: NavSink, offset_m: Sequence[float]) -> NavSink:
    """``sink`` fed with positions shifted by ``offset_m`` (display only): the IMU's, and with them the
    ToF readings' floor hits and the floor height under the IMU, so the views' floor lookups (the
    whole-swing clearance) see hits and track in one frame."""
    off = np.asarray(offset_m, dtype=np.float64)

    def shifted(nav: NavBatch) -> object:
        ranges = nav.ranges
        if ranges is not None:
            ranges = dataclasses.replace(ranges, hit_point_n_m=ranges.hit_point_n_m + off)
        floor = None if nav.floor_z_m is None else nav.floor_z_m + off[2]
        return sink(dataclasses.replace(nav, pos_n_m=nav.pos_n_m + off, ranges=ranges, floor_z_m=floor))

    return shifted


def open_capture(config: Config, session_id: str, *, enabled: bool, extra: dict[str, str]) -> CaptureWriter | None:
    """Create ``<sessions_dir>/<session_id>.mcap`` if capture is on; a folder that cannot be written
    is reported and the session goes on without a capture."""
    if not enabled:
        return None
    path = Path(config["session.sessions_dir"]) / f"{session_id}.mcap"
    flush_s = float(config["session.capture_flush_s"])
    if not flush_s > 0.0:
        where = config.source("session.capture_flush_s")
        raise FootnavError(f"capture_flush_s must be positive, got {flush_s} ({where})")
    try:
        writer = CaptureWriter(path, session={"session_id": session_id, **extra}, flush_period_s=flush_s)
    except OSError as exc:
        notice(f"cannot write the capture {path}: {exc.strerror or exc}; carrying on without a capture")
        return None
    print(f"capturing every byte to {path} (replay it with `footnav replay {path}`)", file=sys.stderr)
    return writer


def unit_header(
    foot: str,
    port: str,
    transport: str,
    config: Config,
    rate_divider_log2: int,
    *,
    extensions: bool = False,
    stance: str = "inertial",
    dual_imu_lever_b_m: tuple[float, float, float] | None = None,
    fused_imu_mask: int | None = None,
    onboard: str | None = None,
    model: UnitModel = DEFAULT_MODEL,
) -> UnitHeader:
    """The capture header of one unit; ``extensions``: the ToF and barometer states were switched on
    (a replay then repeats that handshake); ``stance``: the ToF units' stance detector mode;
    ``dual_imu_lever_b_m``: a dual-IMU board streaming raw 0x28 with that lever arm;
    ``fused_imu_mask``: the raw 0x28 registers of these IMUs, averaged into one IMU; ``onboard``:
    the unit's own solution, "ins" (its INS states :data:`ONBOARD_INS_STATES`) or "steps" (its
    stepwise dead reckoning); ``model``: the unit model told (its base rate gives the rate asked)."""
    dual = {} if dual_imu_lever_b_m is None else {"dual_imu_lever_b_m": list(dual_imu_lever_b_m)}
    fused = {} if fused_imu_mask is None else {"fused_imu_mask": fused_imu_mask}
    mode = "normal_imu" if dual_imu_lever_b_m is None else "dual_imu_raw"
    mode = "raw_imu_fused" if fused_imu_mask is not None else mode
    mode = onboard or mode
    states = {"ins_state_ids": list(ONBOARD_INS_STATES)} if onboard == "ins" else {}
    return UnitHeader(
        foot=foot,
        unit=UNIT_KIND if onboard is None else f"{model.title}, on-board {ONBOARD_TITLES[onboard]}",
        command_set="openshoe (2015 set, 2014 probed)",
        transport=transport,
        port=port,
        settings={
            "mode": mode,
            "model": model.name,
            "rate_divider_log2": rate_divider_log2,
            "rate_hz": model.rate_hz(rate_divider_log2),
            **states,
            "nav_config": config.to_json(),
            "extensions": extensions,
            "stance": stance,
            **dual,
            **fused,
        },
        calibration={
            "on_unit": "factory calibration applied by the unit (calibrated output 0x40)",
            "profile": config["unit.profile"],
        },
    )


@dataclass
class FootRun:
    """One foot of a session: its navigator, its result, its sinks."""

    foot: str
    port: str
    navigator: Navigator | DualNavigator | OnboardInsNavigator | OnboardStepNavigator
    result: SerialSessionResult = field(default_factory=SerialSessionResult)
    tap: CaptureTap | None = None
    health: LinkHealth | None = None
    sinks: list[NavSink] = field(default_factory=list)
    error: BaseException | None = None
    rate_divider_log2: int = 0
    events: GaitEventTracker = field(default_factory=GaitEventTracker)
    """Step onsets and whole-swing clearance of the foot's batches, before any sink sees them."""

    views: SessionViews | None = None
    """The session's views (set by :func:`foot_sinks`)."""
    lead_in_sinks: list[NavSink] = field(default_factory=list)
    """Where the samples before the alignment go once navigated backwards (:meth:`lead_in_sink`): the
    views and the tests' collectors; not the status line, the link health or LSL, whose samples go in
    time order."""

    def finish_events(self) -> None:
        """Hand the views the whole-swing clearance still held when the foot's stream ended."""
        rest = self.events.finish()
        if rest is not None and rest.t_s.size and self.views is not None:
            self.views.log_swing_clearance(rest, foot=self.foot)

    def pipeline_sinks(self) -> list[NavSink]:
        """What the pipeline feeds: every sink, with the batches' gait events filled in."""
        return [self.events.feeding(self.sinks)]

    def add_collector(self, sink: NavSink) -> None:
        """Feed ``sink`` every batch, the lead-in included (the tests' collectors)."""
        self.sinks.append(sink)
        self.lead_in_sinks.append(sink)

    def lead_in_sink(self) -> NavSink:
        """What the session hands the lead-in to (``footnav.app.session.run_unit_session``): every one
        of :attr:`lead_in_sinks`, with its steps found by a tracker of its own."""
        return GaitEventTracker().feeding(self.lead_in_sinks)


def gap_fields(gap: LinkGap | None) -> dict[str, Any]:
    """A gap as JSON-able fields (for the capture's events channel)."""
    if gap is None:
        return {}
    return {
        "reason": gap.reason,
        "start_ns": gap.start_ns,
        "detected_ns": gap.detected_ns,
        "end_ns": gap.end_ns,
        "duration_s": gap.duration_s,
        "reconnect_attempts": gap.reconnect_attempts,
        "last_packet_before": gap.last_packet_before,
        "first_packet_after": gap.first_packet_after,
        "packets_missing": gap.packets_missing,
    }


def link_reporter(
    run: FootRun, views: SessionViews | None, capture: CaptureWriter | None, *, two_feet: bool
) -> Callable[[LinkEvent], None]:
    """Report a foot's link events: a notice on the terminal, a text event in the recording, a
    ``link`` event in the capture (with the gap's figures)."""
    prefix = f"{run.foot}: " if two_feet else ""

    def report(event: LinkEvent) -> None:
        text = prefix + event.message
        notice(text)
        if views is not None:
            views.log_event(text, level="INFO" if event.kind in ("reconnected", "resumed") else "WARN")
        if capture is not None:
            capture.event(run.foot, "link", kind=event.kind, message=event.message, **gap_fields(event.gap))

    return report


def rate_reporter(run: FootRun, views: SessionViews | None, *, two_feet: bool) -> Callable[[float, float], None]:
    """Report that a foot's unit streams at another rate than was asked for: a notice on the terminal
    and a warning in the recording."""
    prefix = f"{run.foot}: " if two_feet else ""

    def report(clock_hz: float, asked_hz: float) -> None:
        text = (
            f"{prefix}the unit's clock gives {clock_hz:g} samples/s where {asked_hz:g} were asked for; "
            f"navigating at {clock_hz:g} Hz"
        )
        notice(text)
        if views is not None:
            views.log_event(text, level="WARN")

    return report


def calibration_lookup(
    config: Config,
    foot: str,
    capture: CaptureWriter | None,
    views: SessionViews | None,
    *,
    two_feet: bool,
) -> CalibrationLookup | None:
    """Apply the unit's calibration file (by MCU id) when it connects, if ``calibration.apply``.

    Only when the calibration folder holds a file is the unit asked its MCU id (so sessions without any
    calibration talk to the unit exactly as before). The outcome is a notice on the terminal, a text
    event in the recording and an ``mcu_id`` event in the capture (replay repeats the exchange from it).
    """
    if not config["calibration.apply"]:
        return None
    folder = calibration_dir(config)
    if not any_calibrations(folder):
        return None
    prefix = f"{foot}: " if two_feet else ""

    def report(mcu_id: bytes | None, stored: StoredCalibration | None, note: str) -> None:
        notice(prefix + note)
        if views is not None:
            views.log_event(prefix + note)
        if capture is not None:
            capture.event(
                foot,
                "mcu_id",
                mcu_id=None if mcu_id is None else mcu_id.hex(),
                calibration=None if stored is None else str(stored.path),
                calibration_document=None if stored is None else stored.document(),  # replay applies it
            )

    return CalibrationLookup(find=lambda mcu_id: load_calibration(folder, mcu_id), report=report)


def attach_unit(run: FootRun, unit: OpenShoeUnit) -> None:
    """Point the foot's link-health plot at the unit's counts (lost packets, reconnects)."""
    if run.health is None:
        return
    run.health.stats = lambda: unit.stats
    link = unit.link
    if isinstance(link, ReconnectingLink):
        run.health.reconnects = lambda: link.health.reconnects


def link_summary(run: FootRun) -> str:
    """One line on a foot's link at the end of a session."""
    lost = run.result.link.lost_packets if run.result.link is not None else 0
    rejected = ""
    if (stats := run.result.link) is not None and (stats.corrupt_numbers or stats.implausible_rejected):
        rejected = f"; rejected: {stats.corrupt_numbers} corrupt numbers, {stats.implausible_rejected} implausible"
    line = f"samples received: {run.result.samples_received} (lost packets: {lost}{rejected})"
    health = run.result.link_health
    if health is not None:
        still_open = ", the last one still open at the end" if health.gaps and health.gaps[-1].end_ns is None else ""
        line += (
            f"; link: {health.reconnects} reconnects, {health.stalls} stalls, {len(health.gaps)} gaps "
            f"({health.downtime_s:.2f} s without data, {health.packets_missing} packets missing{still_open})"
        )
    if handled := input_handling(run.navigator.stats):
        line += f"; {handled}"
    return line + lead_in_note(run.navigator.stats).replace(", ", "; ", 1)


def foot_sinks(
    run: FootRun, views: SessionViews | None, status: StatusLine, *, two_feet: bool, put_timeout_s: float = 0.0
) -> None:
    """Wire a foot to the views (display-offset when two feet), the status line and link health
    (the LSL outlets, with ``--lsl``, are wired by :func:`open_lsl_outlets`)."""
    run.sinks = [status.foot(run.foot)]
    run.lead_in_sinks = [status.foot(run.foot).lead_in]
    run.views = views
    if views is not None:
        display: NavSink = views.sink(run.foot, timeout_s=put_timeout_s)
        if two_feet:
            display = offset_sink(display, FOOT_START_OFFSET_M[run.foot])
        run.health = LinkHealth(views.log_link, run.foot, clock_rate_hz=lambda: run.result.clock_rate_hz)
        run.sinks = [display, run.health, *run.sinks]
        run.lead_in_sinks = [display, *run.lead_in_sinks]


BLE_FIRST_FOUND = "ble:first-found"
"""The LSL identity of a unit given as ``ble:`` alone (:func:`lsl_identity`)."""


def lsl_identity(address: UnitAddress) -> str:
    """A live unit's identity in its LSL ``source_id`` (``footnav.views.lsl.source_id``): the serial port,
    or ``ble:NAME`` / ``ble:ADDRESS`` as given; :data:`BLE_FIRST_FOUND` for ``ble:`` alone. The outlets are
    made before the link finds the unit (``--lsl-wait`` holds the session before its first sample) and a
    ``source_id`` cannot change afterwards, so the first unit found is not named: the same id, whichever
    unit answers."""
    if address.transport == "ble" and not address.target:
        return BLE_FIRST_FOUND
    return str(address)


def check_lsl(feet: Sequence[LslFoot] | None) -> None:
    """Fail before a session starts if its ``--lsl`` cannot work (nothing to check without ``--lsl``); say so
    if a ``source_id`` names no unit (:func:`lsl_identity`).

    Raises
    ------
    FootnavError
        pylsl is missing or cannot load liblsl (``footnav.views.lsl.import_pylsl``).
    """
    if feet is None:
        return
    from footnav.views.lsl import import_pylsl

    import_pylsl()
    if any(f.identity == BLE_FIRST_FOUND for f in feet):
        notice(
            f"LSL: with ble: alone the source_id names no unit ({BLE_FIRST_FOUND}); give ble:NAME or ble:ADDRESS "
            "(footnav scan lists them) for an id that LabRecorder finds again"
        )


def open_lsl_outlets(
    feet: Sequence[LslFoot] | None,
    runs: Sequence[FootRun] = (),
    *,
    wait_s: float = 0.0,
    max_buffered_s: int | None = None,
) -> LslOutlets | None:
    """The session's LSL outlets (None without ``--lsl``), each of ``runs`` wired to its foot's outlet, with
    a line on stderr naming the streams; with ``wait_s`` > 0, once every stream has a consumer or ``wait_s``
    has passed (:func:`wait_lsl_consumers`; outlets are closed again if the wait is interrupted).
    ``max_buffered_s``: what each outlet keeps for a lagging consumer (None: liblsl's default). Call it
    inside the ``try`` whose ``finally`` calls :func:`close_lsl_outlets`.

    Raises
    ------
    FootnavError
        pylsl is missing or liblsl failed (``footnav.views.lsl.open_lsl``).
    """
    if feet is None:
        return None
    from footnav.views.lsl import MAX_BUFFERED_S, open_lsl, source_id

    lsl = open_lsl(feet, max_buffered_s=max_buffered_s or MAX_BUFFERED_S)
    names = [f"'footnav {f.foot} navigation' ({source_id(f.identity, f.foot)})" for f in feet]
    print(f"LSL: streaming {', '.join(names)} and 'footnav gait events'", file=sys.stderr)
    try:
        wait_lsl_consumers(lsl, wait_s)
    except BaseException:  # Ctrl-C during the wait: the caller never gets the outlets to close
        close_lsl_outlets(lsl)
        raise
    for run in runs:
        run.sinks.append(lsl.sink(run.foot))
    return lsl


def wait_lsl_consumers(lsl: LslOutlets | None, wait_s: float) -> None:
    """``--lsl-wait``: until every stream has a consumer or ``wait_s`` has passed (0: no wait), in slices
    that Ctrl-C breaks into (``footnav.views.lsl.LslOutlets.wait_for_consumers``)."""
    if lsl is not None and wait_s > 0:
        lsl.wait_for_consumers(wait_s, notice=notice)


async def wait_lsl_consumers_async(lsl: LslOutlets | None, wait_s: float) -> None:
    """:func:`wait_lsl_consumers` on the event loop (a cancelled task stops at once)."""
    if lsl is not None and wait_s > 0:
        await lsl.wait_for_consumers_async(wait_s, notice=notice)


def close_lsl_outlets(lsl: LslOutlets | None) -> None:
    """Close the LSL outlets (if any) and say what went out."""
    if lsl is not None:
        lsl.close()
        print(lsl.summary(), file=sys.stderr)


async def run_feet(
    runs: Sequence[FootRun], session: Callable[[FootRun], Awaitable[Any]], lockstep: FeetLockstep | None = None
) -> None:
    """Run every foot's session at once; a foot whose unit fails is reported and the others carry on.
    With ``lockstep`` (``footnav.pipeline.two_feet.live.lockstep_for``) a foot's session ends once its
    last estimates are out (its lead-in, if it was filled in at the end, with them).

    Raises
    ------
    FootnavError
        every foot failed (the first error).
    """

    async def one(run: FootRun) -> None:
        side = 0 if lockstep is None else lockstep.side(run.foot)
        try:
            await session(run)
            if lockstep is not None:  # its last cells wait for the other foot's samples
                lockstep.end(side)
                while not lockstep.drained(side):
                    await asyncio.sleep(0.02)
        except (FootnavError, OSError) as exc:
            run.error = exc
            if len(runs) > 1:
                notice(f"{run.foot} foot stopped: {exc}")
        finally:
            if lockstep is not None:
                lockstep.end(side)
            run.finish_events()

    trimmer = asyncio.create_task(heap.trim_periodically())
    try:
        await asyncio.gather(*(one(r) for r in runs))
    finally:
        trimmer.cancel()
    errors = [r.error for r in runs if r.error is not None]
    if errors and len(errors) == len(runs):
        raise errors[0] if isinstance(errors[0], FootnavError) else DeviceError(str(errors[0]))
    if lockstep is not None:
        print(lockstep.summary())
    elif len(runs) == 2:
        print("feet independent: each foot navigated on its own")


def finish_capture(capture: CaptureWriter | None, runs: Sequence[FootRun]) -> None:
    """Mark where each foot's live session stopped (a replay stops there too) and close the file."""
    if capture is None:
        return
    for run in runs:
        capture.event(run.foot, "end", samples=run.result.samples_received, error=str(run.error or ""))
    capture.close()
    if capture.rx_bytes == 0:  # no unit ever answered: nothing worth keeping
        capture.path.unlink(missing_ok=True)
        return
    mb = capture.path.stat().st_size / 1e6
    stopped = f"; STOPPED EARLY: {capture.error.strerror or capture.error}" if capture.error else ""
    print(
        f"capture: {capture.path} ({mb:.1f} MB, {capture.messages} reads/writes, "
        f"{capture.write_seconds:.2f} s spent writing{stopped})",
        file=sys.stderr,
    )


def dual_nav_config(nav_config: NavConfig, lever_b_m: tuple[float, float, float]) -> DualNavConfig:
    """The dual-IMU navigator's settings from the single-IMU ones (same profile, detector and gravity)."""
    return DualNavConfig(
        filter=DualEskfConfig(profile=nav_config.profile, gravity_mps2=nav_config.gravity_mps2),
        detector=nav_config.detector,
        lever_b_m=lever_b_m,
    )


def dual_view_sink(navigator: DualNavigator, views: SessionViews, run: str) -> NavSink:
    """A sink that shows the dual-IMU board's own outputs for each batch: both IMUs' tracks (rigidly
    ``C m`` apart) and the constraint residuals (equal rate, equal specific force in stance)."""

    def show(nav: NavBatch) -> None:
        track = navigator.last_track
        if track is None or track.pos1_n_m.shape[0] != len(nav):
            return
        views.log_dual(
            DualRunView(
                t_s=nav.t_s,
                truth_n_m=None,
                tracks_n_m={},
                imu_tracks_n_m={"imu1": track.pos_imu_n_m[:, 0], "imu2": track.pos_imu_n_m[:, 1]},
                residuals={
                    "rate_diff_dps": np.degrees(track.residual_rate_radps),
                    "force_diff_mps2": track.residual_force_mps2,
                },
            ),
            run=run,
        )

    return show


def foot_run(
    foot: str,
    port: str,
    nav_config: NavConfig,
    rate_hz: float,
    *,
    tof: TofConfig | None = None,
    dual_lever_b_m: tuple[float, float, float] | None = None,
    rate_divider_log2: int = 0,
    onboard: str | None = None,
) -> FootRun:
    """One foot of a session, its navigator and gait events made from the session's settings.

    Parameters
    ----------
    foot, port
        The foot's name and where its unit is (shown to the user).
    nav_config
        The single-IMU settings (``Config.nav_config``); the dual-IMU board's are made from them.
    rate_hz
        The unit's output rate, Hz.
    tof
        The ToF settings (``Config.tof_config``); None: the defaults.
    dual_lever_b_m
        The second IMU's position on a dual-IMU board, body axes, m: the board's filter
        (:class:`~footnav.pipeline.dual_imu.navigator.DualNavigator`) instead of the single-IMU one.
    rate_divider_log2
        The unit's rate divider K: every 2**K-th sample of its base rate.
    onboard
        "ins" or "steps": the unit's own solution is shown instead of footnav's
        (:mod:`footnav.device.onboard`).
    """
    navigator: Navigator | DualNavigator | OnboardInsNavigator | OnboardStepNavigator
    if onboard == "ins":
        navigator, events = OnboardInsNavigator(rate_hz), GaitEventTracker()
    elif onboard == "steps":
        navigator, events = OnboardStepNavigator(), GaitEventTracker()
    elif dual_lever_b_m is not None:
        navigator = DualNavigator(dual_nav_config(nav_config, dual_lever_b_m), rate_hz=rate_hz)
        events = GaitEventTracker()
    else:
        tof = tof or TofConfig()
        if nav_config.step_smoothing:
            navigator = StepSmoothingNavigator(nav_config, rate_hz, tof=tof)
        else:
            navigator = Navigator(nav_config, rate_hz, tof=tof)
        events = GaitEventTracker(tof.snap_m)
    return FootRun(foot, port, navigator, rate_divider_log2=rate_divider_log2, events=events)
