"""A unit's samples as a session passes them to the pipeline: on the session's clock (time from the
first sample), within a replay's window, at the sample rate the unit's clock gives, corrected by the
unit's calibration; and what a session leaves behind (:class:`SerialSessionResult`)."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
from collections.abc import AsyncGenerator, AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from footnav.device.links import reconnecting as links
from footnav.device.protocol.extensions import BaroBatch, TofBatch
from footnav.device.protocol.imu import clock_rate_hz
from footnav.device.protocol.ins_states import InsStateBatch
from footnav.device.protocol.raw_imu import RawImuBatch
from footnav.device.protocol.stepwise import StepBatch
from footnav.device.unit import LinkStats, OpenShoeUnit
from footnav.pipeline.aiding.baro import PressureBatch
from footnav.pipeline.aiding.tof_types import RangeBatch
from footnav.pipeline.calibration.model import ImuCalibration
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.runner import BatchNavigator, SourceItem
from footnav.pipeline.samples import ImuBatch
from numpy.typing import NDArray

log = logging.getLogger(__name__)

IDLE_NOTICE_S = 1.0  # a unit that stops streaming is noticed within this long


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


OUTPUT_BATCHES: dict[str, type] = {"raw": RawImuBatch, "ins": InsStateBatch, "steps": StepBatch}
"""The batch type a session passes on for each unit output other than the calibrated IMU's."""


async def _batches_of(unit: OpenShoeUnit, kind: type) -> AsyncGenerator[Any, None]:
    """Only the ``kind`` batches of the unit's stream."""
    async with contextlib.aclosing(unit.batches()) as stream:
        async for batch in stream:
            if isinstance(batch, kind):
                yield batch


def _readings(batch: TofBatch | BaroBatch, t0_s: float, window: tuple[float, float] | None) -> SourceItem | None:
    """A ToF or barometer batch as the pipeline's readings, on the session clock (None: none left)."""
    t_s = batch.t_s - t0_s
    keep = np.ones(t_s.shape, dtype=bool) if window is None else t_s <= window[1]
    if not keep.any():
        return None
    if isinstance(batch, TofBatch):
        return RangeBatch(t_s[keep], batch.sensor[keep], batch.range_m[keep], batch.status[keep])
    return PressureBatch(t_s[keep], batch.pressure_pa[keep])


class _Window:
    """A session's window ``(start, end)`` in session seconds (None: the whole session): samples after
    it are not passed on and end the stream; ``on_window()`` is called at the first sample in it.
    Samples before it are passed on, so that the window starts from the state the session had there
    (a window starting mid-walk holds no still period to align on); the session shows only the
    window (``NavBatch.since``)."""

    def __init__(self, bounds: tuple[float, float] | None, on_window: Callable[[], None] | None) -> None:
        self.bounds = bounds
        self.on_window = on_window
        self.entered = bounds is None

    def ended(self, t_first_s: float) -> bool:
        """Whether a batch starting at ``t_first_s`` (session s) lies after the window's end."""
        return self.bounds is not None and t_first_s > self.bounds[1]

    def trim(self, batch: Any) -> Any:
        """``batch`` (session time) without its samples after the window's end, to the sample (None:
        none left)."""
        if self.bounds is None:
            return batch
        start_s, end_s = self.bounds
        if not self.entered and float(batch.t_s[-1]) >= start_s:
            self.entered = True
            if self.on_window is not None:
                self.on_window()
        keep = batch.t_s <= end_s
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


def _on_session_clock(batch: Any, result: SerialSessionResult) -> Any:
    """A batch of samples (IMU, raw IMU, INS states) with its time rebased to the session's first
    sample (which the first batch sets); a stepwise batch, which has no device time, as it is."""
    if isinstance(batch, StepBatch):
        return batch
    if result.device_t0_s is None:
        result.device_t0_s = float(batch.t_s[0])
        result.first_counter = int(batch.counter[0])
    return dataclasses.replace(batch, t_s=batch.t_s - result.device_t0_s)


async def session_samples(
    unit: OpenShoeUnit,
    result: SerialSessionResult,
    expect_samples: int | None,
    source_done: Callable[[], bool],
    on_idle: Callable[[float], None],
    idle_notice_s: float | None = IDLE_NOTICE_S,
    window: tuple[float, float] | None = None,
    on_window: Callable[[], None] | None = None,
    use_ranges: bool = True,
    output: str = "imu",
    join_samples: int = 0,
) -> AsyncIterator[Any]:
    """The unit's IMU batches (and ToF and barometer readings, when the unit sends them), or the
    batches of another ``output`` (a key of :data:`OUTPUT_BATCHES`: the raw multi-IMU output 0x28 of
    e.g. the dual-IMU board, the unit's INS states, its stepwise dead reckoning), with time rebased to
    the session's first sample; ends after ``expect_samples`` samples (packets of the other outputs)
    or when ``source_done()`` and the link has gone quiet.

    ``window = (start, end)`` in session seconds: the stream ends after ``end``; ``on_window()`` is
    called at the first sample after ``start`` (the samples before it are passed on too, to be
    navigated but not shown: ``footnav.app.session.run_unit_session``).
    Readings before the first IMU sample (no session clock yet) are dropped; ToF readings are dropped
    when not ``use_ranges``. A window needs device time: not for the stepwise output."""
    if window is not None and output == "steps":
        raise ValueError("the stepwise output has no device time to window")
    span = _Window(window, on_window)
    received = 0
    batches = cast(
        AsyncGenerator[Any, None],
        _imu_and_readings(unit, join_samples) if output == "imu" else _batches_of(unit, OUTPUT_BATCHES[output]),
    )
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
                if result.device_t0_s is not None:
                    item = _readings(batch, result.device_t0_s, window)
                    if item is not None:
                        yield item
                continue
            batch = _on_session_clock(batch, result)
            if isinstance(batch, StepBatch):
                received += len(batch)
                result.samples_received = received
                yield batch
                continue
            if span.ended(float(batch.t_s[0])):
                return
            batch = span.trim(batch)
            if batch is None:
                continue
            received += len(batch)
            result.samples_received = received
            yield batch


CLOCK_RATE_TOLERANCE = 0.005
"""A clock rate within this share of the rate asked for is taken for it (a tick of jitter is no other
rate)."""
CLOCK_RATE_HOLD_SAMPLES = 512
"""IMU samples held at most while waiting for the clock to give a rate; then the rate asked for."""


async def at_clock_rate(
    samples: AsyncIterator[Any],
    navigator: BatchNavigator[Any],
    result: SerialSessionResult,
    on_rate: Callable[[float, float], None] | None,
) -> AsyncIterator[Any]:
    """``samples`` unchanged, once the unit's clock has told the sample rate (``clock_rate_hz``):
    until then they are held, and the navigator is retimed to that rate when it was built for one
    more than :data:`CLOCK_RATE_TOLERANCE` away (``on_rate(clock rate, the rate it was built for)`` is
    told). A stream that ends first, or whose clock gives no rate within
    :data:`CLOCK_RATE_HOLD_SAMPLES`, is navigated at the rate the navigator was built for."""
    held: list[Any] = []
    times: list[NDArray[np.float64]] = []
    settled = False
    async for item in samples:
        if settled:
            yield item
            continue
        held.append(item)
        if not isinstance(item, ImuBatch | RawImuBatch | InsStateBatch):
            continue
        times.append(item.t_s)
        t_s = np.concatenate(times)
        rate = clock_rate_hz(t_s)
        if rate is None and t_s.size < CLOCK_RATE_HOLD_SAMPLES:
            continue
        settled = True
        if rate is None:
            log.warning(
                "the unit's clock gave no sample rate in %d samples: navigating at %g Hz", t_s.size, navigator.rate_hz
            )
        else:
            result.clock_rate_hz = rate
            if abs(rate / navigator.rate_hz - 1.0) > CLOCK_RATE_TOLERANCE:
                asked = navigator.rate_hz
                navigator.retime(rate)
                if on_rate is not None:
                    on_rate(rate, asked)
        for h in held:
            yield h
        held = []
    for h in held:
        yield h


async def corrected(samples: AsyncIterator[Any], calibration: ImuCalibration) -> AsyncIterator[Any]:
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


async def fused_imus(samples: AsyncIterator[Any]) -> AsyncIterator[Any]:
    """The raw multi-IMU batches (0x28) as one IMU: the mean of the IMUs' SI readings at each sample,
    as OpenShoe's array firmware averages its IMUs for the calibrated output 0x40 (which assumes their
    axes aligned, as on the MIMU boards); other readings pass through."""
    async for item in samples:
        if isinstance(item, RawImuBatch):
            acc, gyr = item.acc_b_mps2.mean(axis=1), item.gyr_b_radps.mean(axis=1)
            yield ImuBatch(item.t_s, acc, gyr, item.counter, item.host_ns)
        else:
            yield item
