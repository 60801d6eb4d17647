"""Session assembly: a unit (serial port, BLE, or capture replay) -> the pipeline -> sinks, clean shutdown.

Live units are opened through :class:`footnav.device.links.reconnecting.ReconnectingLink`: an unplugged serial unit or a
dropped BLE connection is reconnected with backoff and its stream resumed while the session, its
capture and its outputs go on; each interruption is a :class:`footnav.device.links.reconnecting.LinkEvent` for the
caller
(``on_link_event``) and is counted in the link's :class:`footnav.device.links.reconnecting.LinkHealth`. A port that
does not
exist or is busy when the session starts is still an error at once (no retrying a typo).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
from collections.abc import AsyncGenerator, AsyncIterator, Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np
from footnav.app.status import FootStatus, StatusLine
from footnav.device.errors import DeviceError
from footnav.device.links import reconnecting as links
from footnav.device.links.base import CaptureTap
from footnav.device.links.reconnecting import LinkEvent, ReconnectingLink
from footnav.device.modes import Mode, RawImuMode
from footnav.device.protocol.extensions import BaroBatch, TofBatch
from footnav.device.protocol.imu import clock_rate_hz
from footnav.device.protocol.raw_imu import RawImuBatch
from footnav.device.unit import LinkStats, OpenShoeUnit
from footnav.pipeline.aiding.baro import PressureBatch
from footnav.pipeline.aiding.tof_types import RangeBatch
from footnav.pipeline.calibration.model import CalibrationError, ImuCalibration
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.runner import BatchNavigator, NavSink, SourceItem, run_pipeline
from footnav.pipeline.samples import ImuBatch
from numpy.typing import NDArray

if TYPE_CHECKING:
    from footnav.app.calibration_store import StoredCalibration
    from footnav.device.links.ble import BleBackend

log = logging.getLogger(__name__)

LIVE_READ_INTERVAL_S = 0.010  # coalesce reads: about 10 packets a batch at 1 kHz (see OpenShoeUnit)
IDLE_NOTICE_S = 1.0  # a unit that stops streaming is noticed within this long
LINK_HEALTH_PERIOD_S = 0.5
"""Link health (rate, loss, reconnects) is logged every this much device time."""


@dataclass
class SerialSessionResult:
    """What a session leaves behind for the summary."""

    link: LinkStats | None = None
    first_counter: int | None = None
    last_nav: NavBatch | None = None
    device_t0_s: float | None = None
    unit_stopped_cleanly: bool = False
    samples_received: int = 0
    """Samples handed to the pipeline (a replay of the capture stops after as many)."""
    link_health: links.LinkHealth | None = None
    """Reconnects, stalls and gaps of a live unit's link (None for a replay)."""
    clock_rate_hz: float | None = None
    """The sample rate by the unit's clock (``footnav.device.protocol.imu.clock_rate_hz``), Hz."""


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
    second of host receive time, cumulative lost packets and reconnects.

    Host times come from the batches (in a replay, the captured ones), so replays log the same values.
    """

    def __init__(
        self,
        log: Callable[..., None],
        foot: str,
        stats: Callable[[], LinkStats] | None = None,
        reconnects: Callable[[], int] | None = None,
    ) -> None:
        self._log = log
        self.foot = foot
        self.stats = stats
        self.reconnects = reconnects
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
        self._log(
            foot=self.foot,
            t_s=t_last,
            rate_hz=self._n / span_s if span_s > 0 else float("nan"),
            lost_packets=0 if stats is None else stats.lost_packets,
            reconnects=0 if self.reconnects is None else self.reconnects(),
        )
        self._n, self._host0 = 0, host1
        self._t_next = t_last + LINK_HEALTH_PERIOD_S


async def _raw_batches(unit: OpenShoeUnit) -> AsyncGenerator[RawImuBatch, None]:
    """Only the :class:`RawImuBatch` es of the unit's stream."""
    async with contextlib.aclosing(unit.batches()) as stream:
        async for batch in stream:
            if isinstance(batch, RawImuBatch):
                yield batch


def _readings(batch: TofBatch | BaroBatch, t0_s: float, window: tuple[float, float] | None) -> SourceItem | None:
    """A ToF or barometer batch as the pipeline's readings, on the session clock (None: none left)."""
    t_s = batch.t_s - t0_s
    keep = np.ones(t_s.shape, dtype=bool) if window is None else (t_s >= window[0]) & (t_s <= window[1])
    if not keep.any():
        return None
    if isinstance(batch, TofBatch):
        return RangeBatch(t_s[keep], batch.sensor[keep], batch.range_m[keep], batch.status[keep])
    return PressureBatch(t_s[keep], batch.pressure_pa[keep])


class _Window:
    """A session's window ``(start, end)`` in session seconds (None: the whole session): samples before
    it are decoded but not passed on, ``on_window()`` is called at the first one passed on."""

    def __init__(self, bounds: tuple[float, float] | None, on_window: Callable[[], None] | None) -> None:
        self.bounds = bounds
        self.on_window = on_window
        self.entered = bounds is None

    def ended(self, t_first_s: float) -> bool:
        """Whether a batch starting at ``t_first_s`` (session s) lies after the window's end."""
        return self.bounds is not None and t_first_s > self.bounds[1]

    def trim(self, batch: ImuBatch) -> ImuBatch | None:
        """``batch`` (session time) trimmed to the window to the sample, whatever the batching (None:
        none of it in the window)."""
        if self.bounds is None:
            return batch
        start_s, end_s = self.bounds
        if not self.entered:
            if float(batch.t_s[-1]) < start_s:
                return None
            self.entered = True
            if self.on_window is not None:
                self.on_window()
        keep = (batch.t_s >= start_s) & (batch.t_s <= end_s)
        if keep.all():
            return batch
        return batch.select(keep) if keep.any() else None


async def _arrivals(
    batches: AsyncGenerator[Any, None],
    idle_notice_s: float | None,
    source_done: Callable[[], bool],
    on_idle: Callable[[float], None],
) -> AsyncGenerator[Any, None]:
    """The stream's batches as they arrive. With ``idle_notice_s``, ``on_idle(idle_notice_s)`` each time
    none came for that long, and the end once ``source_done()`` while idle; None (a replay): never idle,
    and no task per batch."""
    if idle_notice_s is None:
        async for batch in batches:
            yield batch
        return
    # The pending anext survives idle timeouts: cancelling it (asyncio.wait_for) would end the generator.
    pending: asyncio.Future[Any] | None = None
    try:
        while True:
            if pending is None:
                pending = asyncio.ensure_future(anext(batches))
            done, _ = await asyncio.wait({pending}, timeout=idle_notice_s)
            if not done:
                if source_done():
                    return
                on_idle(idle_notice_s)
                continue
            fut, pending = pending, None
            try:
                batch = fut.result()
            except StopAsyncIteration:
                return
            yield batch
    finally:
        if pending is not None and not pending.done():
            pending.cancel()
            with contextlib.suppress(asyncio.CancelledError, StopAsyncIteration):
                await pending


def _on_session_clock(
    batch: ImuBatch, result: SerialSessionResult, host_clock: Callable[[int], int] | None
) -> ImuBatch:
    """An IMU batch with its time rebased to the session's first sample (which the first batch sets),
    and its host stamps mapped by ``host_clock`` (per read: a joined batch holds several)."""
    if host_clock is not None:
        stamps, read_of = np.unique(batch.host_ns, return_inverse=True)
        mapped = np.array([host_clock(int(h)) for h in stamps], dtype=np.int64)
        batch = dataclasses.replace(batch, host_ns=mapped[read_of])
    if result.device_t0_s is None:
        result.device_t0_s = float(batch.t_s[0])
        result.first_counter = int(batch.counter[0])
    return dataclasses.replace(batch, t_s=batch.t_s - result.device_t0_s)


async def _session_samples(
    unit: OpenShoeUnit,
    result: SerialSessionResult,
    expect_samples: int | None,
    source_done: Callable[[], bool],
    on_idle: Callable[[float], None],
    host_clock: Callable[[int], int] | None = None,
    idle_notice_s: float | None = IDLE_NOTICE_S,
    window: tuple[float, float] | None = None,
    on_window: Callable[[], None] | None = None,
    use_ranges: bool = True,
    raw: bool = False,
    join_samples: int = 0,
) -> AsyncIterator[Any]:
    """The unit's IMU batches (and ToF and barometer readings, when the unit sends them; or, with
    ``raw``, the ``RawImuBatch`` es of the multi-IMU output 0x28 of e.g. the dual-IMU board) with time
    rebased to the session's first sample; ends after ``expect_samples`` IMU samples or when
    ``source_done()`` and the link has gone quiet.

    ``host_clock`` maps the driver's host stamp of a batch to another (a replay's captured time).
    ``window = (start, end)`` in session seconds: samples outside it are decoded but not
    passed on (``on_window()`` is called at the first one passed on), the stream ends after ``end``.
    Readings before the first IMU sample (no session clock yet) are dropped; ToF readings are dropped
    when not ``use_ranges``."""
    span = _Window(window, on_window)
    received = 0
    batches = cast(AsyncGenerator[Any, None], _raw_batches(unit) if raw else _imu_and_readings(unit, join_samples))
    arrivals = _arrivals(batches, idle_notice_s, source_done, on_idle)
    async with contextlib.aclosing(batches), contextlib.aclosing(arrivals):
        while expect_samples is None or received < expect_samples:
            try:
                batch = await anext(arrivals)
            except StopAsyncIteration:
                return
            if isinstance(batch, TofBatch | BaroBatch):
                if isinstance(batch, TofBatch) and not use_ranges:
                    continue
                if result.device_t0_s is not None and span.entered:
                    item = _readings(batch, result.device_t0_s, window)
                    if item is not None:
                        yield item
                continue
            batch = _on_session_clock(batch, result, host_clock)
            if span.ended(float(batch.t_s[0])):
                return
            batch = span.trim(batch)
            if batch is None:
                continue
            received += len(batch)
            result.samples_received = received
            yield batch


async def _at_clock_rate(
    samples: AsyncIterator[Any],
    navigator: BatchNavigator[Any],
    result: SerialSessionResult,
    on_rate: Callable[[float, float], None] | None,
) -> AsyncIterator[Any]:
    """``samples`` unchanged, once the unit's clock has told the sample rate (``clock_rate_hz``):
    until then they are held, and the navigator is retimed to that rate when it was built for
    another (``on_rate(clock rate, the rate it was built for)`` is told). A stream that ends first
    is navigated at the rate the navigator was built for."""
    held: list[Any] = []
    times: list[NDArray[np.float64]] = []
    async for item in samples:
        if result.clock_rate_hz is not None:
            yield item
            continue
        held.append(item)
        if isinstance(item, ImuBatch | RawImuBatch):
            times.append(item.t_s)
            rate = clock_rate_hz(np.concatenate(times))
            if rate is None:
                continue
            result.clock_rate_hz = rate
            if not math.isclose(rate, navigator.rate_hz, rel_tol=1e-9):
                nominal = navigator.rate_hz
                navigator.retime(rate)
                if on_rate is not None:
                    on_rate(rate, nominal)
            for h in held:
                yield h
            held = []
    for h in held:
        yield h


async def _corrected(samples: AsyncIterator[Any], calibration: ImuCalibration) -> AsyncIterator[Any]:
    """The calibration stage before the navigator: every IMU batch corrected (no temperature in the
    stream); other readings pass through."""
    async for item in samples:
        yield calibration.correct(item) if isinstance(item, ImuBatch) else item


async def _imu_and_readings(
    unit: OpenShoeUnit, join_samples: int = 0
) -> AsyncGenerator[ImuBatch | TofBatch | BaroBatch, None]:
    """The IMU, ToF and barometer batches of :meth:`OpenShoeUnit.batches`, in arrival order.

    ``join_samples > 0``: consecutive IMU batches are joined until they hold that many samples (or
    another kind of batch, or the end, comes). For a replay at full speed, whose reads are all there
    at once: the unit still frames and orders each captured read as it did live, and everything
    after it pays its per-batch cost once per join instead of once per read."""
    held: list[ImuBatch] = []
    held_samples = 0
    async with contextlib.aclosing(unit.batches()) as stream:
        async for batch in stream:
            if not isinstance(batch, ImuBatch | TofBatch | BaroBatch):
                continue
            if isinstance(batch, ImuBatch) and join_samples > 0:
                held.append(batch)
                held_samples += len(batch)
                if held_samples >= join_samples:
                    yield ImuBatch.concat(held)
                    held, held_samples = [], 0
                continue
            if held:
                yield ImuBatch.concat(held)
                held, held_samples = [], 0
            yield batch
        if held:
            yield ImuBatch.concat(held)


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
    0xE1/0xE2); their readings go to the navigator; ``on_rate``: see :func:`run_unit_session`.

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
    )


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
    host_clock: Callable[[int], int] | None = None,
    idle_notice_s: float | None = IDLE_NOTICE_S,
    window: tuple[float, float] | None = None,
    on_window: Callable[[], None] | None = None,
    calibration: CalibrationLookup | None = None,
    mode: Mode | None = None,
    extensions: bool = False,
    use_ranges: bool = True,
    join_samples: int = 0,
    on_rate: Callable[[float, float], None] | None = None,
) -> SerialSessionResult:
    """Navigate an open unit's stream (see :func:`run_device_session`); ``start=False`` for a replay,
    where the captured bytes already hold the start and no stop is sent; ``idle_notice_s=None`` never
    treats a pause as idle (replays); ``window``: see ``_session_samples``; ``calibration``: ask the
    unit its MCU id before the start and apply its calibration file (a replay passes one only when the
    capture holds that exchange); ``mode``: the output mode (see :func:`run_device_session`);
    ``extensions``: switch the ToF and barometer states on after the start; ``use_ranges=False``
    leaves the ToF readings out of the navigation; ``join_samples``: IMU batches joined to this
    many samples (a replay at full speed: ``_imu_and_readings``); the navigator runs at the rate
    the unit's clock gives (``_at_clock_rate``; ``on_rate(clock rate, rate asked for)`` when they
    differ). Closes the unit."""
    result = result if result is not None else SerialSessionResult()
    name = unit.link.name

    def keep_last(nav: NavBatch) -> None:
        result.last_nav = nav

    link = unit.link if isinstance(unit.link, ReconnectingLink) else None

    def idle(seconds: float) -> None:
        if link is not None and link.health.gaps and link.health.gaps[-1].end_ns is None:
            return  # the link reports its own gaps (stall, disconnect, reconnect)
        log.warning("no data from %s for %.1f s", name, seconds)

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
            if mode is None:
                await unit.start_imu_stream(rate_divider_log2)
            else:
                await unit.start(mode)
            if extensions:
                await unit.enable_extensions(tof=True, baro=True)
        samples = _session_samples(
            unit,
            result,
            expect_samples,
            source_done,
            on_idle or idle,
            host_clock,
            idle_notice_s,
            window,
            on_window,
            use_ranges,
            raw=isinstance(mode, RawImuMode),
            join_samples=join_samples,
        )
        samples = _at_clock_rate(samples, navigator, result, on_rate)
        if stored is not None and mode is None:
            samples = _corrected(samples, stored.calibration)
        await run_pipeline(samples, navigator, [*sinks, keep_last])
    finally:
        result.link = unit.stats
        if start:
            with contextlib.suppress(DeviceError, OSError):
                result.unit_stopped_cleanly = await asyncio.shield(unit.stop())
        with contextlib.suppress(DeviceError, OSError):
            await asyncio.shield(unit.close())
    return result
