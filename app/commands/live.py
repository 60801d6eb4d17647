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
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from footnav.app import heap
from footnav.app.config import DEFAULT, Config
from footnav.app.feet import (
    ONBOARD_INS_STATES,
    ONBOARD_TITLES,
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
    link_summary,
    lsl_identity,
    new_session_id,
    notice,
    open_capture,
    open_lsl_outlets,
    rate_reporter,
    run_feet,
    unit_header,
    wait_lsl_consumers_async,
)
from footnav.app.session import UnitAddress, run_device_session, unit_mode
from footnav.app.status import StatusLine
from footnav.device.files.capture import CaptureWriter
from footnav.device.models import DEFAULT_MODEL, UnitModel, unit_model
from footnav.device.onboard import OnboardInsNavigator, OnboardStepNavigator
from footnav.device.protocol.raw_imu import DUAL_IMU_MASK
from footnav.pipeline.dual_imu.navigator import DualNavigator
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.runner import NavSink
from footnav.pipeline.two_feet.live import LOCKSTEP_MAX_LEAD_S, FeetLockstep, lockstep_for
from footnav.views.lsl import LslRequest, lsl_feet
from footnav.views.outputs import SessionViews, open_session_views

if TYPE_CHECKING:
    from footnav.device.links.ble import BleBackend

BLE_RATE_DIVIDER = 2
"""Over BLE the default is 250 Hz: 34-byte packets at 1 kHz (34 kB/s) need more than a typical link
carries (about 16 kB/s at ATT MTU 23 and 6 notifications per 7.5 ms connection event)."""


INS_RATE_DIVIDER = {"serial": 2, "ble": 5}
"""The default rate divider of the unit's INS states (230-byte packets with the covariance): 250 Hz
over USB, 31.25 Hz (7 kB/s) over BLE, on a 1 kHz unit."""


def rate_divider_for(address: UnitAddress, config: Config, output: str = "imu") -> int:
    """The unit's rate divider: the configured one, except by default over BLE (:data:`BLE_RATE_DIVIDER`,
    250 Hz) and for the INS states (:data:`INS_RATE_DIVIDER`); asking for 1 kHz over BLE is allowed,
    with a warning."""
    k = int(config["unit.rate_divider"])
    default = config.source("unit.rate_divider") == DEFAULT
    if output == "ins" and default:
        return INS_RATE_DIVIDER[address.transport]
    if address.transport != "ble":
        return k
    if default:
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
    lsl
        ``--lsl``: stream the estimates on Lab Streaming Layer too (:mod:`footnav.views.lsl`).
    feet_coupling
        two feet: coupled by the distance bound, with the relative heading too, or independent
        (``footnav.pipeline.two_feet.live``: the feet's clocks matched by host time).
    """

    ports: dict[str, str]
    config: Config
    save: Path | None = None
    viewer: bool = True
    web: bool = False
    keep_web: bool = False
    capture: bool = True
    argv: tuple[str, ...] = ()
    ble_backend: BleBackend | None = None
    collect: Callable[[str], NavSink] | None = None
    tof: bool = False
    stance: str = "inertial"
    dual_imu_lever_b_m: tuple[float, float, float] | None = None
    fused_imu_mask: int | None = None
    output: str = "auto"
    model: str | None = None
    lsl: LslRequest | None = None
    feet_coupling: str = "distance"


def choose_output(opts: LiveOptions, model: UnitModel) -> str:
    """The output to stream (``footnav.device.models.OUTPUTS``) for what was asked, checked against
    the model and the other options.

    Raises
    ------
    FootnavError
        the model lacks the output, or the options contradict each other.
    """
    dual, fused = opts.dual_imu_lever_b_m, opts.fused_imu_mask
    if dual is not None and opts.tof:
        raise FootnavError("a unit is either a dual-IMU board or a ToF unit: give --dual-imu or --tof, not both")
    if fused is not None and (dual is not None or opts.tof):
        raise FootnavError("--mode raw streams the raw IMUs of a unit without ToF; drop --dual-imu and --tof")
    output = opts.output
    if output == "auto":
        output = "raw" if fused is not None or dual is not None else model.default_output
    if output not in model.outputs:
        raise FootnavError(
            f"the {model.title} streams {', '.join(model.outputs)}, not --mode {output}"
            + (" (--dual-imu streams the raw output)" if dual is not None else "")
        )
    if output in ONBOARD_TITLES and (dual is not None or opts.tof):
        raise FootnavError(f"--mode {output} shows the unit's own solution: drop --dual-imu and --tof")
    if dual is not None and output != "raw":
        raise FootnavError("--dual-imu streams both IMUs' raw output: drop --mode or give --mode raw")
    return output


def stepwise_fallback(
    run: FootRun,
    views: SessionViews | None,
    capture: CaptureWriter | None,
    *,
    two_feet: bool,
    lockstep: FeetLockstep | None = None,
) -> Callable[[str], OnboardStepNavigator]:
    """What a foot does when its unit's firmware offers stepwise output only: say so (terminal,
    recording, capture event, which a replay follows) and show the unit's stepwise dead reckoning
    (out of the feet's ``lockstep``, if they were coupled)."""

    def fall_back(reason: str) -> OnboardStepNavigator:
        if lockstep is not None:
            lockstep.end(lockstep.side(run.foot))
        text = (f"{run.foot}: " if two_feet else "") + f"{reason}; showing the unit's stepwise dead reckoning"
        notice(text)
        if views is not None:
            views.log_event(text, level="WARN")
        if capture is not None:
            capture.event(run.foot, "mode", mode="steps")
        navigator = OnboardStepNavigator()
        run.navigator = navigator
        return navigator

    return fall_back


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
        return 130  # the shell's code for a command ended by Ctrl-C (SIGINT)


def _model(opts: LiveOptions) -> UnitModel:
    """The unit's model (``--unit``); its IMU's profile unless the configuration names one."""
    if opts.model is None:
        return DEFAULT_MODEL
    model = unit_model(opts.model)
    if opts.config.source("unit.profile") == DEFAULT:
        opts.config.set("unit.profile", model.imu, f"--unit {model.name}")
    return model


async def live_session(opts: LiveOptions) -> int:
    """:func:`run_live` on the running event loop (cancel it to stop, as Ctrl-C does)."""
    cfg = opts.config
    model = _model(opts)
    output = choose_output(opts, model)
    rate_divider = int(cfg["unit.rate_divider"])
    top = model.max_rate_divider(output)
    if not 0 <= rate_divider <= top:
        what = "the raw output 0x28" if output == "raw" else "the unit's outputs"
        raise FootnavError(
            f"rate divider must be 0..{top} for {what}, got {rate_divider} ({cfg.source('unit.rate_divider')})"
        )
    texts = list(opts.ports.values())
    if len(set(texts)) < len(texts):
        same = next(t for t in texts if texts.count(t) > 1)
        raise FootnavError(
            f"one unit ({same or 'ble:'}) is given for two feet; each foot needs its own unit (--left and --right)"
        )
    addresses = {foot: UnitAddress.parse(text) for foot, text in opts.ports.items()}
    dividers = {foot: rate_divider_for(address, cfg, output) for foot, address in addresses.items()}
    feet = tuple(opts.ports)
    two_feet = len(feet) > 1
    session_id = new_session_id("live")
    dual, fused = opts.dual_imu_lever_b_m, opts.fused_imu_mask
    if output == "raw" and dual is None and fused is None:
        fused = (1 << model.imus) - 1  # every IMU of the board, averaged
    onboard = output if output in ONBOARD_TITLES else None
    lsl_streams = lsl_feet(
        opts.lsl,
        {foot: lsl_identity(address) for foot, address in addresses.items()},
        units=model.title,
        rates={foot: 0.0 if onboard == "steps" else model.rate_hz(k) for foot, k in dividers.items()},
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
        dual_runs=feet if dual is not None else (),
        tof=opts.tof,
        rrd_footer=False,  # a live session's length is open: its memory must stay flat
    )
    for note in notes:
        print(note, file=sys.stderr)
    extra = {"command": " ".join(opts.argv), "feet_coupling": opts.feet_coupling}  # a two-feet replay's too
    capture = open_capture(cfg, session_id, enabled=opts.capture, extra=extra)
    status = StatusLine(feet=feet)
    nav_config = cfg.nav_config()

    tof = cfg.tof_config(opts.stance)
    runs = [
        foot_run(
            foot,
            str(addresses[foot]),
            nav_config,
            model.rate_hz(dividers[foot]),
            tof=tof,
            dual_lever_b_m=dual,
            rate_divider_log2=dividers[foot],
            onboard=onboard,
        )
        for foot in feet
    ]
    for run in runs:
        foot_sinks(run, views, status, two_feet=two_feet)
        if views is not None and isinstance(run.navigator, DualNavigator):
            run.sinks.append(dual_view_sink(run.navigator, views, run.foot))
        if opts.collect is not None:
            run.add_collector(opts.collect(run.foot))
        if capture is not None:
            run.tap = capture.add_unit(
                unit_header(
                    run.foot,
                    run.port,
                    addresses[run.foot].transport,
                    cfg,
                    run.rate_divider_log2,
                    extensions=opts.tof,
                    stance=opts.stance,
                    dual_imu_lever_b_m=dual,
                    fused_imu_mask=fused,
                    onboard=onboard,
                    model=model,
                )
            )
    probing = opts.output == "auto" and opts.model is None  # 2014 firmware: its stepwise output instead
    lockstep = lockstep_for(
        {run.foot: run.navigator for run in runs},
        opts.feet_coupling,
        max_lead_s=LOCKSTEP_MAX_LEAD_S,
        log_event=getattr(views, "log_event", None),
        notice=notice,
    )

    async def session(run: FootRun) -> None:
        await run_device_session(
            addresses[run.foot],
            run.navigator if lockstep is None else lockstep.port_for(run.foot),
            run.pipeline_sinks(),
            lead_in=run.lead_in_sink(),
            rate_divider_log2=run.rate_divider_log2,
            status=status.foot(run.foot),
            result=run.result,
            capture=run.tap,
            on_open=lambda unit: attach_unit(run, unit),
            on_link_event=link_reporter(run, views, capture, two_feet=two_feet),
            ble_backend=opts.ble_backend,
            calibration=calibration_lookup(cfg, run.foot, capture, views, two_feet=two_feet)
            if output == "imu"
            else None,
            extensions=opts.tof,
            mode=unit_mode(
                output, run.rate_divider_log2, DUAL_IMU_MASK if fused is None else fused, ONBOARD_INS_STATES
            ),
            fuse_imus=fused is not None,
            on_rate=rate_reporter(run, views, two_feet=two_feet),
            on_stepwise_only=stepwise_fallback(run, views, capture, two_feet=two_feet, lockstep=lockstep)
            if probing
            else None,
        )

    if views is not None:
        views.log_event(f"live session {session_id}: " + ", ".join(_foot_line(run, addresses, model) for run in runs))
    lsl = None
    try:
        lsl = open_lsl_outlets(lsl_streams, runs)
        await wait_lsl_consumers_async(lsl, opts.lsl.wait_s if opts.lsl else 0.0)
        await run_feet(runs, session, lockstep)
    finally:
        status.finish()
        finish_capture(capture, runs)
        _close_views(views, opts, runs)
        close_lsl_outlets(lsl)
        for run in runs:
            if run.result.samples_received:
                print((f"{run.foot}: " if two_feet else "") + link_summary(run))
    return 0


def _close_views(views: SessionViews | None, opts: LiveOptions, runs: Sequence[FootRun]) -> None:
    """Close the session's outputs; a recording file nobody asked for (no ``--save``) is removed when
    no unit sent a sample."""
    if views is None:
        return
    for note in views.close():
        notice(note)
    if opts.save is None and not any(run.result.samples_received for run in runs):
        for path in (out.path for out in views.outputs if out.path is not None):
            path.unlink(missing_ok=True)
            notice(f"no unit sent data: the empty recording {path} was removed")


def _foot_line(run: FootRun, addresses: dict[str, UnitAddress], model: UnitModel) -> str:
    """A foot's unit, where it is and what it streams, for the session's first event."""
    where = f"{run.foot} on {addresses[run.foot].description}"
    if isinstance(run.navigator, OnboardStepNavigator):
        return f"{where}: the unit's stepwise dead reckoning"
    what = "the unit's INS states at" if isinstance(run.navigator, OnboardInsNavigator) else "at"
    return f"{where}: {what} {model.rate_hz(run.rate_divider_log2):g} Hz asked"
