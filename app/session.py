"""Session assembly: a unit on a serial port -> the pipeline -> sinks, with a clean shutdown."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
from collections.abc import AsyncGenerator, AsyncIterator, Callable, Sequence
from dataclasses import dataclass
from typing import cast

from app.status import StatusLine
from device.unit import LinkStats, OpenShoeUnit
from pipeline.errors import DeviceError
from pipeline.nav_types import NavBatch
from pipeline.navigator import Navigator
from pipeline.runner import NavSink, run_pipeline
from pipeline.samples import ImuBatch

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


async def _session_samples(
    unit: OpenShoeUnit,
    result: SerialSessionResult,
    expect_samples: int | None,
    source_done: Callable[[], bool],
    on_idle: Callable[[float], None],
) -> AsyncIterator[ImuBatch]:
    """The unit's batches with time rebased to the session's first sample; ends after
    ``expect_samples`` or when ``source_done()`` and the link has gone quiet."""
    received = 0
    batches = cast(AsyncGenerator[ImuBatch, None], unit.imu_batches())
    async with contextlib.aclosing(batches):
        while expect_samples is None or received < expect_samples:
            try:
                batch = await asyncio.wait_for(anext(batches), IDLE_NOTICE_S)
            except StopAsyncIteration:
                return
            except TimeoutError:
                if source_done():
                    return
                on_idle(IDLE_NOTICE_S)
                continue
            if result.device_t0_s is None:
                result.device_t0_s = float(batch.t_s[0])
                result.first_counter = int(batch.counter[0])
            received += len(batch)
            yield dataclasses.replace(batch, t_s=batch.t_s - result.device_t0_s)


async def run_serial_session(
    port: str,
    navigator: Navigator,
    sinks: Sequence[NavSink],
    *,
    rate_divider_log2: int = 0,
    expect_samples: int | None = None,
    source_done: Callable[[], bool] = lambda: False,
    on_idle: Callable[[float], None] | None = None,
    status: StatusLine | None = None,
    result: SerialSessionResult | None = None,
) -> SerialSessionResult:
    """Open ``port``, start the unit's IMU stream, navigate until the stream ends or the task is
    cancelled (Ctrl-C), then stop the unit and close the port whatever happened.

    ``result`` (optional) is filled in as the session goes, so an interrupted session still has one.

    Raises:
        DeviceError: the port cannot be opened, the unit does not answer, or it was unplugged.
    """
    result = result if result is not None else SerialSessionResult()

    def keep_last(nav: NavBatch) -> None:
        result.last_nav = nav

    def idle(seconds: float) -> None:
        log.warning("no data from %s for %.1f s", port, seconds)

    unit = await OpenShoeUnit.open_serial(port)
    if status is not None:
        status.lost_packets = lambda: unit.stats.lost_packets
    try:
        await unit.start_imu_stream(rate_divider_log2)
        samples = _session_samples(unit, result, expect_samples, source_done, on_idle or idle)
        await run_pipeline(samples, navigator, [*sinks, keep_last])
    finally:
        result.link = unit.stats
        with contextlib.suppress(DeviceError, OSError):
            result.unit_stopped_cleanly = await asyncio.shield(unit.stop())
        with contextlib.suppress(DeviceError, OSError):
            await asyncio.shield(unit.close())
    return result
