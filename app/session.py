"""Session assembly: a unit (serial port, BLE, or capture replay) -> the pipeline -> sinks, clean shutdown.

Live units are opened through :class:`footnav.device.links.reconnecting.ReconnectingLink`: an unplugged
serial unit or a dropped BLE connection is reconnected with backoff and its stream resumed while the
session, its capture and its outputs go on; each interruption is a
:class:`footnav.device.links.reconnecting.LinkEvent` for the caller (``on_link_event``) and is counted in
the link's :class:`footnav.device.links.reconnecting.LinkHealth`. A port that does not exist or is busy
when the session starts is still an error at once (no retrying a typo). The samples' way from the unit
to the pipeline is :mod:`footnav.app.stream`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

from footnav.app.status import FootStatus, StatusLine
from footnav.app.stream import IDLE_NOTICE_S, SerialSessionResult, at_clock_rate, corrected, fused_imus, session_samples
from footnav.device.errors import DeviceError, UnsupportedModeError
from footnav.device.links.base import CaptureTap
from footnav.device.links.reconnecting import LinkEvent, ReconnectingLink
from footnav.device.modes import InsMode, Mode, NormalImuMode, RawImuMode, StepwiseMode
from footnav.device.unit import LinkStats, OpenShoeUnit
from footnav.pipeline.calibration.model import CalibrationError
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.lead_in import LiveLeadIn
from footnav.pipeline.navigation.navigator import Navigator
from footnav.pipeline.runner import BatchNavigator, NavSink, run_pipeline
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.two_feet.live import LockstepPort

if TYPE_CHECKING:
    from footnav.app.calibration_store import StoredCalibration
    from footnav.device.links.ble import BleBackend

log = logging.getLogger(__name__)

LIVE_READ_INTERVAL_S = 0.010  # coalesce reads: about 10 packets a batch at 1 kHz (see OpenShoeUnit)
STEPWISE_IDLE_NOTICE_S = 5.0
"""A stepwise unit sends a packet per step and about one a second while standing: silence is told
after this long, s."""
LINK_HEALTH_PERIOD_S = 0.5
"""Link health (rate, loss, reconnects) is logged every this much device time."""


def _shown_since(start_s: float, sinks: Sequence[NavSink]) -> NavSink:
    """One sink that passes the estimates at or after ``start_s`` to ``sinks`` (a replay's window: the
    samples before it are navigated, not shown)."""

    def show(nav: NavBatch) -> None:
        part = nav.since(start_s)
        if part is not None:
            for sink in sinks:
                sink(part)

    return show


class _FillingIn:
    """The navigator as the runner drives it, with its lead-in filled in (``footnav.pipeline.navigation.lead_in
    .LiveLeadIn``): handed to ``sink`` once, as one batch earlier than those already given."""

    def __init__(self, navigator: Navigator, sink: NavSink) -> None:
        self.navigator, self.sink = navigator, sink
        self.lead_in = LiveLeadIn(navigator)

    @property
    def rate_hz(self) -> float:
        return self.navigator.rate_hz

    def retime(self, rate_hz: float) -> None:
        self.navigator.retime(rate_hz)

    def add_ranges(self, batch: Any) -> None:
        self.navigator.add_ranges(batch)

    def add_pressure(self, batch: Any) -> None:
        self.navigator.add_pressure(batch)

    def process(self, batch: ImuBatch) -> NavBatch | None:
        self.lead_in.add(batch)
        nav = self.navigator.process(batch)
        if (lead_in := self.lead_in.after(nav)) is not None:
            self.sink(lead_in)
        return nav

    def finish(self) -> None:
        """At the end of the stream: the lead-in whose still period lasted to it."""
        if (lead_in := self.lead_in.finish()) is not None:
            self.sink(lead_in)


def _filling_in(
    navigator: BatchNavigator[Any],
    lead_in: NavSink | None,
    window: tuple[float, float] | None,
    mode: Mode | None,
    fuse_imus: bool,
) -> _FillingIn | None:
    """The navigator with its lead-in handed to ``lead_in`` (shown within a replay's ``window``), if
    it is a single-IMU one fed IMU samples (the calibrated output, or ``fuse_imus``) and ``lead_in``
    is given. A coupled foot (``footnav.pipeline.two_feet.live.LockstepPort``) is told to fill its
    lead-in in itself, as its lockstep navigates it (and at the foot's end): None is returned."""
    if lead_in is None or not (mode is None or fuse_imus):
        return None
    shown = lead_in if window is None else _shown_since(window[0], [lead_in])
    if isinstance(navigator, LockstepPort):
        navigator.fill_lead_in(shown)
        return None
    if not isinstance(navigator, Navigator):
        return None
    return _FillingIn(navigator, shown)


async def _navigate(
    samples: AsyncIterator[Any], navigator: BatchNavigator[Any], sinks: Sequence[NavSink], filling: _FillingIn | None
) -> None:
    """``run_pipeline``, through ``filling`` when given: its lead-in is filled in at the end of the
    stream too, or when the session is stopped."""
    if filling is None:
        await run_pipeline(samples, navigator, sinks)
        return
    try:
        await run_pipeline(samples, filling, sinks)
    finally:
        filling.finish()


def _idle_notice_s(mode: Mode | None, idle_notice_s: float | None) -> float | None:
    """How long a silence is before it is told: longer for the stepwise output (a packet a step)."""
    if isinstance(mode, StepwiseMode) and idle_notice_s is not None:
        return max(idle_notice_s, STEPWISE_IDLE_NOTICE_S)
    return idle_notice_s


def unit_mode(output: str, rate_divider_log2: int, imu_mask: int, ins_state_ids: tuple[int, ...]) -> Mode | None:
    """What to start on the unit for ``output`` (None: the calibrated IMU output 0x40); the inverse of
    :func:`output_of`."""
    if output == "raw":
        return RawImuMode(imu_mask=imu_mask, rate_divider_log2=rate_divider_log2)
    if output == "ins":
        return InsMode(state_ids=ins_state_ids, rate_divider_log2=rate_divider_log2)
    if output == "steps":
        return StepwiseMode()
    return None


def output_of(mode: Mode | None) -> str:
    """The ``footnav.app.stream.session_samples`` output a mode streams (None: the calibrated IMU's)."""
    if isinstance(mode, RawImuMode):
        return "raw"
    if isinstance(mode, InsMode):
        return "ins"
    if isinstance(mode, StepwiseMode):
        return "steps"
    return "imu"


@dataclass(frozen=True)
class CalibrationLookup:
    """How a session finds the connected unit's calibration and tells the user.

    Before the unit is started it is asked its MCU id (``OpenShoeUnit.request_mcu_id``); ``find(mcu_id)``
    returns its calibration file or None (and may raise ``CalibrationError`` for an unreadable one);
    ``report(mcu_id, stored, note)`` is told the outcome (``mcu_id`` None: the unit did not answer).
    The calibration then corrects every batch before the navigator (at its reference temperature:
    the calibrated-IMU stream 0x40 carries no temperature).
    """

    find: Callable[[bytes], StoredCalibration | None]
    report: Callable[[bytes | None, StoredCalibration | None, str], None]
    mcu_id_timeout_s: float = 1.0


async def _unit_calibration(unit: OpenShoeUnit, lookup: CalibrationLookup) -> StoredCalibration | None:
    """Ask the unit its MCU id and look its calibration up; failures are reported, never fatal."""
    try:
        mcu_id = await unit.request_mcu_id(timeout_s=lookup.mcu_id_timeout_s)
    except DeviceError as exc:
        lookup.report(None, None, f"{exc}; navigating without a calibration file")
        return None
    try:
        stored = lookup.find(mcu_id)
    except CalibrationError as exc:
        lookup.report(mcu_id, None, f"{exc}; navigating without it")
        return None
    if stored is None:
        note = f"no calibration file for the unit (MCU id {mcu_id.hex()}); `footnav calibrate` makes one"
    else:
        note = (
            f"applying {stored.describe()}; the 0x40 stream carries no temperature, so the model is "
            "evaluated at its reference temperature"
        )
    lookup.report(mcu_id, stored, note)
    return stored


@dataclass(frozen=True, slots=True)
class UnitAddress:
    """Where a live unit is: a serial port, or a BLE unit by advertised name or address.

    Written ``PORT`` (``/dev/ttyACM0``, ``COM3``) or ``ble:NAME|ADDRESS``; ``ble:`` alone (or ``ble``)
    means the first unit advertising a known UART service.
    """

    transport: Literal["serial", "ble"]
    target: str | None
    """The port (serial), or the BLE name or address (None: the first unit found)."""

    @classmethod
    def parse(cls, text: str) -> UnitAddress:
        if text.lower() == "ble":
            return cls("ble", None)
        if text[:4].lower() == "ble:":
            return cls("ble", text[4:].strip() or None)
        return cls("serial", text)

    def __str__(self) -> str:
        if self.transport == "serial":
            return self.target or ""
        return f"ble:{self.target or ''}"

    @property
    def description(self) -> str:
        """For messages: the port, or "BLE unit NAME"."""
        if self.transport == "serial":
            return self.target or ""
        return f"BLE unit {self.target}" if self.target else "the first BLE shoe unit"


async def open_unit_link(
    address: UnitAddress,
    *,
    on_event: Callable[[LinkEvent], None] | None = None,
    capture: CaptureTap | None = None,
    ble_backend: BleBackend | None = None,
) -> ReconnectingLink:
    """Open a reconnecting link to ``address`` (bytes the link writes itself go to ``capture`` too).

    Raises
    ------
    DeviceError
        the port does not exist or is busy, no Bluetooth stack, the BLE unit is not found.
    """
    if address.transport == "ble":
        link = ReconnectingLink.ble(address.target, backend=ble_backend, on_event=on_event, tx_tap=capture)
    else:
        assert address.target is not None
        link = ReconnectingLink.serial(address.target, on_event=on_event, tx_tap=capture)
    await link.open()
    return link


class LinkHealth:
    """A NavSink that logs link health every :data:`LINK_HEALTH_PERIOD_S` of device time: samples per
    second of host receive time, the rate by the unit's clock, cumulative lost packets and reconnects.

    Host times come from the batches (in a replay, the captured ones), so replays log the same values.
    """

    def __init__(
        self,
        log: Callable[..., None],
        foot: str,
        stats: Callable[[], LinkStats] | None = None,
        reconnects: Callable[[], int] | None = None,
        clock_rate_hz: Callable[[], float | None] | None = None,
    ) -> None:
        self._log = log
        self.foot = foot
        self.stats = stats
        self.reconnects = reconnects
        self.clock_rate_hz = clock_rate_hz
        self._t_next: float | None = None
        self._n = 0
        self._host0: int | None = None

    def __call__(self, nav: NavBatch) -> None:
        if self._host0 is None:
            self._host0 = int(nav.host_ns[0])
            self._t_next = float(nav.t_s[0]) + LINK_HEALTH_PERIOD_S
        self._n += len(nav)
        t_last = float(nav.t_s[-1])
        assert self._t_next is not None
        if t_last < self._t_next:
            return
        host1 = int(nav.host_ns[-1])
        span_s = (host1 - self._host0) / 1e9
        stats = self.stats() if self.stats is not None else None
        clock = None if self.clock_rate_hz is None else self.clock_rate_hz()
        self._log(
            foot=self.foot,
            t_s=t_last,
            rate_hz=self._n / span_s if span_s > 0 else float("nan"),
            lost_packets=0 if stats is None else stats.lost_packets,
            reconnects=0 if self.reconnects is None else self.reconnects(),
            clock_rate_hz=float("nan") if clock is None else clock,
        )
        self._n, self._host0 = 0, host1
        self._t_next = t_last + LINK_HEALTH_PERIOD_S


async def run_device_session(
    address: UnitAddress,
    navigator: BatchNavigator[Any],
    sinks: Sequence[NavSink],
    *,
    rate_divider_log2: int = 0,
    expect_samples: int | None = None,
    source_done: Callable[[], bool] = lambda: False,
    on_idle: Callable[[float], None] | None = None,
    status: StatusLine | FootStatus | None = None,
    result: SerialSessionResult | None = None,
    capture: CaptureTap | None = None,
    on_open: Callable[[OpenShoeUnit], None] | None = None,
    on_link_event: Callable[[LinkEvent], None] | None = None,
    ble_backend: BleBackend | None = None,
    calibration: CalibrationLookup | None = None,
    mode: Mode | None = None,
    extensions: bool = False,
    on_rate: Callable[[float, float], None] | None = None,
    fuse_imus: bool = False,
    on_stepwise_only: Callable[[str], BatchNavigator[Any]] | None = None,
    lead_in: NavSink | None = None,
) -> SerialSessionResult:
    """Open the unit at ``address`` through a :class:`~footnav.device.links.reconnecting.ReconnectingLink`, start
    its IMU
    stream, navigate until the stream ends or the task is cancelled (Ctrl-C), then stop the unit and
    close the link whatever happened.

    An unplugged unit or a dropped BLE connection is reconnected with backoff and its stream resumed
    (the learned start command is sent again); the session waits meanwhile and carries on. Every
    :class:`~footnav.device.links.reconnecting.LinkEvent` goes to ``on_link_event``; the counts are in
    ``result.link_health``, and the status line shows the reconnects.

    ``result`` (optional) is filled in as the session goes, so an interrupted session still has one.
    ``capture`` sees every byte read and written (the capture file), including the start commands the
    link re-sends on its own; ``on_open`` is called with the unit once the link is open;
    ``ble_backend``: the bleak backend for BLE units (None: the platform's; tests pass bumble's);
    ``calibration``: look the unit's calibration file up by its MCU id and apply it (see
    :class:`CalibrationLookup`);
    ``mode``: the output mode to start (None: the calibrated-IMU stream at ``rate_divider_log2``);
    ``RawImuMode`` streams ``RawImuBatch`` es (e.g. the dual-IMU board) to a matching navigator;
    ``extensions``: also switch on the unit's ToF and barometer states (footnav's extension states
    0xE1/0xE2); their readings go to the navigator; ``on_rate``, ``fuse_imus``, ``on_stepwise_only``,
    ``lead_in``: see :func:`run_unit_session`.

    Raises
    ------
    DeviceError
        the port does not exist or is busy, no Bluetooth stack, the unit is not found or
        does not answer the start command.
    """
    link = await open_unit_link(address, on_event=on_link_event, capture=capture, ble_backend=ble_backend)
    unit = OpenShoeUnit(link, capture=capture, read_interval_s=LIVE_READ_INTERVAL_S)
    if on_open is not None:
        on_open(unit)
    return await run_unit_session(
        unit,
        navigator,
        sinks,
        rate_divider_log2=rate_divider_log2,
        expect_samples=expect_samples,
        source_done=source_done,
        on_idle=on_idle,
        status=status,
        result=result,
        calibration=calibration,
        mode=mode,
        extensions=extensions,
        on_rate=on_rate,
        fuse_imus=fuse_imus,
        on_stepwise_only=on_stepwise_only,
        lead_in=lead_in,
    )


def unit_name(link_name: str, status: StatusLine | FootStatus | None) -> str:
    """How a warning names a unit: its link, with the foot when a session has two (its ``FootStatus`` is
    ``left`` or ``right``)."""
    if isinstance(status, FootStatus) and status.name in ("left", "right"):
        return f"the {status.name} foot's unit ({link_name})"
    return link_name


async def _start(
    unit: OpenShoeUnit,
    mode: Mode | None,
    rate_divider_log2: int,
    navigator: BatchNavigator[Any],
    on_stepwise_only: Callable[[str], BatchNavigator[Any]] | None,
) -> tuple[Mode | None, BatchNavigator[Any]]:
    """Start ``mode`` (None: the calibrated IMU output); on firmware with stepwise output only, that
    instead when ``on_stepwise_only`` gives its navigator. Returns the mode started and the navigator."""
    try:
        await unit.start(NormalImuMode(rate_divider_log2) if mode is None else mode)
    except UnsupportedModeError as exc:
        if on_stepwise_only is None:
            raise
        navigator = on_stepwise_only(str(exc))
        mode = StepwiseMode()
        await unit.start(mode)
    return mode, navigator


async def run_unit_session(
    unit: OpenShoeUnit,
    navigator: BatchNavigator[Any],
    sinks: Sequence[NavSink],
    *,
    start: bool = True,
    rate_divider_log2: int = 0,
    expect_samples: int | None = None,
    source_done: Callable[[], bool] = lambda: False,
    on_idle: Callable[[float], None] | None = None,
    status: StatusLine | FootStatus | None = None,
    result: SerialSessionResult | None = None,
    idle_notice_s: float | None = IDLE_NOTICE_S,
    window: tuple[float, float] | None = None,
    on_window: Callable[[], None] | None = None,
    calibration: CalibrationLookup | None = None,
    mode: Mode | None = None,
    extensions: bool = False,
    use_ranges: bool = True,
    join_samples: int = 0,
    on_rate: Callable[[float, float], None] | None = None,
    fuse_imus: bool = False,
    on_stepwise_only: Callable[[str], BatchNavigator[Any]] | None = None,
    lead_in: NavSink | None = None,
) -> SerialSessionResult:
    """Navigate an open unit's stream (see :func:`run_device_session`); ``start=False`` for a replay,
    where the captured bytes already hold the start and no stop is sent; ``idle_notice_s=None`` never
    treats a pause as idle (replays); ``window``: see ``footnav.app.stream.session_samples``; ``calibration``: ask the
    unit its MCU id before the start and apply its calibration file (a replay passes one only when the
    capture holds that exchange); ``mode``: the output mode (see :func:`run_device_session`);
    ``extensions``: switch the ToF and barometer states on after the start; ``use_ranges=False``
    leaves the ToF readings out of the navigation; ``join_samples``: IMU batches joined to this
    many samples (a replay at full speed: ``footnav.app.stream``); the navigator runs at the rate
    the unit's clock gives (``footnav.app.stream.at_clock_rate``; ``on_rate(clock rate, rate asked for)`` when they
    differ); ``fuse_imus``: a ``RawImuMode`` stream's IMUs averaged into one IMU for a single-IMU
    navigator (``footnav.app.stream.fused_imus``); ``on_stepwise_only(reason)``: the firmware offers
    stepwise output only (2014 MIMU22BT): start that instead, with the navigator this returns (for
    ``footnav.device.onboard.OnboardStepNavigator``), rather than fail; ``lead_in``: where the
    samples before the alignment go once navigated backwards (:class:`_FillingIn`, or a coupled foot's
    lockstep; a single-IMU navigator's IMU samples only). Closes the unit."""
    result = result if result is not None else SerialSessionResult()
    name = unit.link.name

    def keep_last(nav: NavBatch) -> None:
        result.last_nav = nav

    link = unit.link if isinstance(unit.link, ReconnectingLink) else None

    def idle(seconds: float) -> None:
        if link is not None and link.health.gaps and link.health.gaps[-1].end_ns is None:
            return  # the link reports its own gaps (stall, disconnect, reconnect)
        log.warning("no data from %s for %.1f s", unit_name(name, status), seconds)

    if isinstance(status, FootStatus):
        status.clock_rate_hz = lambda: result.clock_rate_hz
    if status is not None:
        status.lost_packets = lambda: unit.stats.lost_packets
    if link is not None:
        result.link_health = link.health
        if status is not None:
            status.reconnects = lambda: link.health.reconnects
    try:
        stored = None
        if start and calibration is not None:
            stored = await _unit_calibration(unit, calibration)
        if start:
            mode, navigator = await _start(unit, mode, rate_divider_log2, navigator, on_stepwise_only)
            if extensions:
                await unit.enable_extensions(tof=True, baro=True)
        samples = session_samples(
            unit,
            result,
            expect_samples,
            source_done,
            on_idle or idle,
            _idle_notice_s(mode, idle_notice_s),
            window,
            on_window,
            use_ranges,
            output=output_of(mode),
            join_samples=join_samples,
        )
        if fuse_imus:
            samples = fused_imus(samples)
        if not isinstance(mode, StepwiseMode):  # steps carry no device clock
            samples = at_clock_rate(samples, navigator, result, on_rate)
        if stored is not None and mode is None:
            samples = corrected(samples, stored.calibration)
        shown = sinks if window is None else [_shown_since(window[0], sinks)]
        await _navigate(
            samples, navigator, [*shown, keep_last], _filling_in(navigator, lead_in, window, mode, fuse_imus)
        )
    finally:
        result.link = unit.stats
        if start:
            with contextlib.suppress(DeviceError, OSError):
                result.unit_stopped_cleanly = await asyncio.shield(unit.stop())
        with contextlib.suppress(DeviceError, OSError):
            await asyncio.shield(unit.close())
    return result
