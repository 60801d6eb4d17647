"""``footnav live``: one unit or two (left and right foot), each with its own navigator, shown together.

Units are on USB serial (``/dev/ttyACM0``) or BLE (``ble:NAME|ADDRESS``; 250 Hz by default there).
Each foot is built by :func:`footnav.app.feet.foot_run`, as in ``demo`` and ``replay``: the capture
file (every byte, both directions, written by the unit driver's tap before any decoding), the Rerun
outputs (one recording, one ``recording_id``), the one-line status of every foot, and link health.
Link faults (unplug, BLE drop, a unit that stops streaming) are reconnected by
:class:`footnav.device.links.reconnecting.ReconnectingLink`; each event is reported on the terminal,
as a text event in the recording and as a ``link`` event in the capture.

Tests only: :attr:`LiveOptions.ble_backend` injects a bleak backend (bumble's virtual radio) and
:attr:`LiveOptions.collect` an extra sink per foot; neither is reachable from the command line.
"""

from __future__ import annotations

import asyncio
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from footnav.app import heap
from footnav.app.config import DEFAULT, Config
from footnav.app.feet import (
    BASE_RATE_HZ,
    FootRun,
    attach_unit,
    calibration_lookup,
    dual_view_sink,
    finish_capture,
    foot_run,
    foot_sinks,
    link_reporter,
    link_summary,
    new_session_id,
    notice,
    open_capture,
    rate_reporter,
    run_feet,
    unit_header,
)
from footnav.app.session import UnitAddress, run_device_session
from footnav.app.status import StatusLine
from footnav.device.modes import RawImuMode
from footnav.device.protocol.commands import MAX_RATE_DIVIDER_LOG2, MAX_RAW_RATE_DIVIDER_LOG2
from footnav.device.protocol.raw_imu import DUAL_IMU_MASK
from footnav.pipeline.dual_imu.navigator import DualNavigator
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.runner import NavSink
from footnav.views.outputs import open_session_views

if TYPE_CHECKING:
    from footnav.device.links.ble import BleBackend

BLE_RATE_DIVIDER = 2
"""Over BLE the default is 250 Hz: 34-byte packets at 1 kHz (34 kB/s) need more than a typical link
carries (about 16 kB/s at ATT MTU 23 and 6 notifications per 7.5 ms connection event)."""


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


@dataclass(frozen=True)
class LiveOptions:
    """What ``footnav live`` was asked for.

    Attributes
    ----------
    ports
        foot name -> unit address: a serial port, or ``ble:NAME|ADDRESS`` (``ble:`` alone: the
        first BLE unit found); ``{"foot": ...}`` for one unit, ``left``/``right`` for two.
    ble_backend
        tests only (never set by the command line): the bleak backend for BLE units, e.g.
        ``footnav.device.emulator.serving.ble_backend.bumble_backend(adapter)``; None = the platform's.
    collect
        tests only: an extra NavSink per foot (given the foot name).
    tof
        switch on the units' ToF and barometer extension states and fuse the ToF readings.
    dual_imu_lever_b_m
        the units are dual-IMU boards with IMU 2 at this lever arm in IMU 1's
        axes, m: their raw two-IMU output (0x28, mask 0b11) goes to the dual-IMU navigator.
    fused_imu_mask
        stream the raw registers (0x28) of the IMUs in this mask and navigate their mean as one IMU
        (``footnav.app.stream.fused_imus``) instead of the unit's calibrated output 0x40.
    stance
        stance detector mode with ToF units (``footnav.pipeline.stance.height_detector.HeightDetectorParams``).
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
    fused_imu_mask: int | None = None


def run_live(opts: LiveOptions) -> int:
    """Navigate one or two connected units until Ctrl-C; returns the exit code.

    Raises
    ------
    FootnavError
        a port cannot be opened, a unit does not answer (all feet failed).
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
    raw_output = opts.dual_imu_lever_b_m is not None or opts.fused_imu_mask is not None
    top = MAX_RAW_RATE_DIVIDER_LOG2 if raw_output else MAX_RATE_DIVIDER_LOG2
    if not 0 <= rate_divider <= top:
        what = "the raw output 0x28" if raw_output else "the calibrated IMU output"
        raise FootnavError(
            f"rate divider must be 0..{top} for {what}, got {rate_divider} ({cfg.source('unit.rate_divider')})"
        )
    addresses = {foot: UnitAddress.parse(text) for foot, text in opts.ports.items()}
    dividers = {foot: rate_divider_for(address, cfg) for foot, address in addresses.items()}
    feet = tuple(opts.ports)
    two_feet = len(feet) > 1
    session_id = new_session_id("live")
    dual = opts.dual_imu_lever_b_m
    if dual is not None and opts.tof:
        raise FootnavError("a unit is either a dual-IMU board or a ToF unit: give --dual-imu or --tof, not both")
    fused = opts.fused_imu_mask
    if fused is not None and (dual is not None or opts.tof):
        raise FootnavError("--mode raw streams the raw IMUs of a unit without ToF; drop --dual-imu and --tof")
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

    tof = cfg.tof_config(opts.stance)
    runs = [
        foot_run(
            foot,
            str(addresses[foot]),
            nav_config,
            BASE_RATE_HZ / 2 ** dividers[foot],
            tof=tof,
            dual_lever_b_m=dual,
            rate_divider_log2=dividers[foot],
        )
        for foot in feet
    ]
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
                    fused_imu_mask=fused,
                )
            )

    async def session(run: FootRun) -> None:
        mask = fused if fused is not None else DUAL_IMU_MASK
        raw = RawImuMode(imu_mask=mask, rate_divider_log2=run.rate_divider_log2)
        await run_device_session(
            addresses[run.foot],
            run.navigator,
            run.pipeline_sinks(),
            rate_divider_log2=run.rate_divider_log2,
            status=status.foot(run.foot),
            result=run.result,
            capture=run.tap,
            on_open=lambda unit: attach_unit(run, unit),
            on_link_event=link_reporter(run, views, capture, two_feet=two_feet),
            ble_backend=opts.ble_backend,
            calibration=None
            if dual is not None or fused is not None
            else calibration_lookup(cfg, run.foot, capture, views, two_feet=two_feet),
            extensions=opts.tof,
            mode=raw if dual is not None or fused is not None else None,
            fuse_imus=fused is not None,
            on_rate=rate_reporter(run, views, two_feet=two_feet),
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
