"""``footnav live``: one unit or two (left and right foot), each with its own navigator, shown together.

Units are on USB serial (``/dev/ttyACM0``) or BLE (``ble:NAME|ADDRESS``; 250 Hz by default there).
Shared by ``live`` and ``demo``: the capture file (every byte, both directions, written by the unit
driver's tap before any decoding), the Rerun outputs (one recording, one ``recording_id``), the
one-line status of every foot, and link health. Link faults (unplug, BLE drop, a unit that stops
streaming) are reconnected by :class:`footnav.device.links.reconnecting.ReconnectingLink`; each event is reported on the
terminal, as a text event in the recording and as a ``link`` event in the capture.

Tests only: :attr:`LiveOptions.ble_backend` injects a bleak backend (bumble's virtual radio) and
:attr:`LiveOptions.collect` an extra sink per foot; neither is reachable from the command line.
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
from footnav.app.config import DEFAULT, Config
from footnav.app.session import CalibrationLookup, LinkHealth, SerialSessionResult, UnitAddress, run_device_session
from footnav.app.status import StatusLine, input_handling
from footnav.device.errors import DeviceError
from footnav.device.files.capture import CaptureTap, CaptureWriter, UnitHeader
from footnav.device.links.reconnecting import LinkEvent, LinkGap, ReconnectingLink
from footnav.device.protocol.raw_imu import DUAL_IMU_MASK
from footnav.device.unit import OpenShoeUnit, RawImuMode
from footnav.pipeline.dual_imu.board_eskf import DualEskfConfig
from footnav.pipeline.dual_imu.navigator import DualNavConfig, DualNavigator
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavConfig, Navigator
from footnav.pipeline.runner import NavSink
from footnav.pipeline.smoothing.stepwise import make_navigator
from footnav.views.dual_imu import DualRunView
from footnav.views.outputs import SessionViews, open_session_views

if TYPE_CHECKING:
    from footnav.device.links.ble import BleBackend

FOOT_START_OFFSET_M: dict[str, tuple[float, float, float]] = {
    "left": (0.0, 0.1, 0.0),
    "right": (0.0, -0.1, 0.0),
}
"""Where each foot's navigation origin is drawn: two feet start side by side, 0.2 m apart (each
navigator starts at its own origin; this offset is for display only)."""

UNIT_KIND = "OpenShoe/MIMU/Oblu, calibrated IMU output (0x40)"
BASE_RATE_HZ = 1000.0
BLE_RATE_DIVIDER = 2
"""Over BLE the default is 250 Hz: 34-byte packets at 1 kHz (34 kB/s) need more than a typical link
carries (about 16 kB/s at ATT MTU 23 and 6 notifications per 7.5 ms connection event)."""


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
) -> UnitHeader:
    """The capture header of one unit; ``extensions``: the ToF and barometer states were switched on
    (a replay then repeats that handshake); ``stance``: the ToF units' stance detector mode;
    ``dual_imu_lever_b_m``: a dual-IMU board streaming raw 0x28 with that lever arm."""
    dual = {} if dual_imu_lever_b_m is None else {"dual_imu_lever_b_m": list(dual_imu_lever_b_m)}
    return UnitHeader(
        foot=foot,
        unit=UNIT_KIND,
        command_set="openshoe (2015 set, 2014 probed)",
        transport=transport,
        port=port,
        settings={
            "mode": "normal_imu" if dual_imu_lever_b_m is None else "dual_imu_raw",
            "rate_divider_log2": rate_divider_log2,
            "rate_hz": BASE_RATE_HZ / 2**rate_divider_log2,
            "nav_config": config.to_json(),
            "extensions": extensions,
            "stance": stance,
            **dual,
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
    navigator: Navigator | DualNavigator
    result: SerialSessionResult = field(default_factory=SerialSessionResult)
    tap: CaptureTap | None = None
    health: LinkHealth | None = None
    sinks: list[NavSink] = field(default_factory=list)
    error: BaseException | None = None
    rate_divider_log2: int = 0


def rate_divider_for(address: UnitAddress, config: Config) -> int:
    """The unit's rate divider: the configured one, except over BLE where the default is
    :data:`BLE_RATE_DIVIDER` (250 Hz); asking for 1 kHz over BLE is allowed, with a warning."""
    k = int(config["unit.rate_divider"])
    if address.transport != "ble":
        return k
    if config.source("unit.rate_divider") == DEFAULT:
        return BLE_RATE_DIVIDER
    if k == 0:
        notice(
            f"warning: 1 kHz over BLE ({address.description}, rate divider 0 from "
            f"{config.source('unit.rate_divider')}) needs about 34 kB/s, more than most BLE links carry "
            f"(about 16 kB/s at the minimum MTU): expect lost packets; --rate-divider {BLE_RATE_DIVIDER} "
            f"(250 Hz) is the BLE default"
        )
    return k


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
    line = f"samples received: {run.result.samples_received} (lost packets: {lost})"
    health = run.result.link_health
    if health is not None:
        still_open = ", the last one still open at the end" if health.gaps and health.gaps[-1].end_ns is None else ""
        line += (
            f"; link: {health.reconnects} reconnects, {health.stalls} stalls, {len(health.gaps)} gaps "
            f"({health.downtime_s:.2f} s without data, {health.packets_missing} packets missing{still_open})"
        )
    if handled := input_handling(run.navigator.stats):
        line += f"; {handled}"
    return line


def foot_sinks(
    run: FootRun, views: SessionViews | None, status: StatusLine, *, two_feet: bool, put_timeout_s: float = 0.0
) -> None:
    """Wire a foot to the views (display-offset when two feet), the status line and link health."""
    run.sinks = [status.foot(run.foot)]
    if views is not None:
        display: NavSink = views.sink(run.foot, timeout_s=put_timeout_s)
        if two_feet and run.foot in FOOT_START_OFFSET_M:
            display = offset_sink(display, FOOT_START_OFFSET_M[run.foot])
        run.health = LinkHealth(views.log_link, run.foot)
        run.sinks = [display, run.health, *run.sinks]


async def run_feet(runs: Sequence[FootRun], session: Callable[[FootRun], Awaitable[Any]]) -> None:
    """Run every foot's session at once; a foot whose unit fails is reported and the others carry on.

    Raises:
        FootnavError: every foot failed (the first error).
    """

    async def one(run: FootRun) -> None:
        try:
            await session(run)
        except (FootnavError, OSError) as exc:
            run.error = exc
            if len(runs) > 1:
                notice(f"{run.foot} foot stopped: {exc}")

    trimmer = asyncio.create_task(heap.trim_periodically())
    try:
        await asyncio.gather(*(one(r) for r in runs))
    finally:
        trimmer.cancel()
    errors = [r.error for r in runs if r.error is not None]
    if errors and len(errors) == len(runs):
        raise errors[0] if isinstance(errors[0], FootnavError) else DeviceError(str(errors[0]))


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


@dataclass(frozen=True)
class LiveOptions:
    """What ``footnav live`` was asked for.

    Attributes:
        ports: foot name -> unit address: a serial port, or ``ble:NAME|ADDRESS`` (``ble:`` alone: the
            first BLE unit found); ``{"foot": ...}`` for one unit, ``left``/``right`` for two.
        ble_backend: tests only (never set by the command line): the bleak backend for BLE units, e.g.
            ``footnav.device.emulator.serving.ble_backend.bumble_backend(adapter)``; None = the platform's.
        collect: tests only: an extra NavSink per foot (given the foot name).
        tof: switch on the units' ToF and barometer extension states and fuse the ToF readings.
        dual_imu_lever_b_m: the units are dual-IMU boards with IMU 2 at this lever arm in IMU 1's
            axes, m: their raw two-IMU output (0x28, mask 0b11) goes to the dual-IMU navigator.
        stance: stance detector mode with ToF units (``footnav.pipeline.stance.height_detector.HeightDetectorParams``).
    """

    ports: dict[str, str]
    config: Config
    save: Path | None = None
    viewer: bool = True
    web: bool = False
    capture: bool = True
    argv: tuple[str, ...] = ()
    ble_backend: BleBackend | None = None
    collect: Callable[[str], NavSink] | None = None
    tof: bool = False
    stance: str = "inertial"
    dual_imu_lever_b_m: tuple[float, float, float] | None = None


def run_live(opts: LiveOptions) -> int:
    """Navigate one or two connected units until Ctrl-C; returns the exit code.

    Raises:
        FootnavError: a port cannot be opened, a unit does not answer (all feet failed).
    """
    try:
        return asyncio.run(live_session(opts))
    except KeyboardInterrupt:
        print("stopped: the unit was told to stop and the recording was closed", file=sys.stderr)
    return 0


async def live_session(opts: LiveOptions) -> int:
    """:func:`run_live` on the running event loop (cancel it to stop, as Ctrl-C does)."""
    cfg = opts.config
    rate_divider = int(cfg["unit.rate_divider"])
    if not 0 <= rate_divider <= 6:
        raise FootnavError(f"rate divider must be 0..6, got {rate_divider} ({cfg.source('unit.rate_divider')})")
    addresses = {foot: UnitAddress.parse(text) for foot, text in opts.ports.items()}
    dividers = {foot: rate_divider_for(address, cfg) for foot, address in addresses.items()}
    feet = tuple(opts.ports)
    two_feet = len(feet) > 1
    session_id = new_session_id("live")
    dual = opts.dual_imu_lever_b_m
    if dual is not None and opts.tof:
        raise FootnavError("a unit is either a dual-IMU board or a ToF unit: give --dual-imu or --tof, not both")
    heap.limit_arenas()  # before the viewer's and the capture's threads start
    views, notes = open_session_views(
        save=opts.save,
        want_viewer=opts.viewer,
        web=opts.web,
        feet=feet,
        recording_id=session_id,
        notice=notice,
        dual_runs=feet if dual is not None else (),
        rrd_footer=False,  # a live session's length is open: its memory must stay flat
    )
    for note in notes:
        print(note, file=sys.stderr)
    capture = open_capture(cfg, session_id, enabled=opts.capture, extra={"command": " ".join(opts.argv)})
    status = StatusLine(feet=feet)
    nav_config = cfg.nav_config()

    def navigator(foot: str) -> Navigator | DualNavigator:
        rate_hz = BASE_RATE_HZ / 2 ** dividers[foot]
        if dual is not None:
            return DualNavigator(dual_nav_config(nav_config, dual), rate_hz=rate_hz)
        return make_navigator(nav_config, rate_hz, tof=cfg.tof_config(opts.stance))

    runs = [FootRun(foot, str(addresses[foot]), navigator(foot), rate_divider_log2=dividers[foot]) for foot in feet]
    for run in runs:
        foot_sinks(run, views, status, two_feet=two_feet)
        if views is not None and isinstance(run.navigator, DualNavigator):
            run.sinks.append(dual_view_sink(run.navigator, views, run.foot))
        if opts.collect is not None:
            run.sinks.append(opts.collect(run.foot))
        if capture is not None:
            transport = addresses[run.foot].transport
            run.tap = capture.add_unit(
                unit_header(
                    run.foot,
                    run.port,
                    transport,
                    cfg,
                    run.rate_divider_log2,
                    extensions=opts.tof,
                    stance=opts.stance,
                    dual_imu_lever_b_m=dual,
                )
            )

    async def session(run: FootRun) -> None:
        raw = RawImuMode(imu_mask=DUAL_IMU_MASK, rate_divider_log2=run.rate_divider_log2)
        await run_device_session(
            addresses[run.foot],
            run.navigator,
            run.sinks,
            rate_divider_log2=run.rate_divider_log2,
            status=status.foot(run.foot),
            result=run.result,
            capture=run.tap,
            on_open=lambda unit: attach_unit(run, unit),
            on_link_event=link_reporter(run, views, capture, two_feet=two_feet),
            ble_backend=opts.ble_backend,
            calibration=calibration_lookup(cfg, run.foot, capture, views, two_feet=two_feet) if dual is None else None,
            extensions=opts.tof,
            mode=raw if dual is not None else None,
        )

    if views is not None:
        views.log_event(
            f"live session {session_id}: "
            + ", ".join(f"{f} on {addresses[f].description} at {BASE_RATE_HZ / 2 ** dividers[f]:g} Hz" for f in feet)
        )
    try:
        await run_feet(runs, session)
    finally:
        status.finish()
        finish_capture(capture, runs)
        if views is not None:
            for note in views.close():
                notice(note)
        for run in runs:
            if run.result.samples_received:
                print((f"{run.foot}: " if two_feet else "") + link_summary(run))
    return 0
