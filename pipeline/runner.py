"""The stage runner: samples in, estimates out to every sink, over bounded asyncio queues.

    source ──▶ [queue] ──▶ navigator ──▶ sinks (callables, each must return quickly)

The source yields IMU sample batches and, from units that have them, ToF range and barometer
readings, in the order they arrived; readings are queued in the navigator, which applies them when
its IMU samples reach their time (``Navigator.add_ranges``, ``add_pressure``).

The queue is bounded, so a slow estimator pushes back on the source (the OS and the unit buffer the
bytes; the capture, written by the source, never drops anything). Sinks must not block: the Rerun
logger, for example, only enqueues for its own thread. This is the only module of ``pipeline`` that
knows asyncio.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable, Sequence
from typing import Any, Protocol, TypeVar, cast

from footnav.pipeline.aiding.baro import PressureBatch
from footnav.pipeline.aiding.tof_types import RangeBatch
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.samples import ImuBatch

NavSink = Callable[[NavBatch], object]  # return values are ignored
SourceItem = ImuBatch | RangeBatch | PressureBatch
"""What a single-IMU source yields (a dual-IMU source yields two-IMU batches only)."""

BatchT_contra = TypeVar("BatchT_contra", contravariant=True)
B = TypeVar("B")


class BatchNavigator(Protocol[BatchT_contra]):
    """What the runner drives: ``footnav.pipeline.navigation.navigator.Navigator`` (``ImuBatch``) or
    ``footnav.pipeline.dual_imu.navigator.DualNavigator`` (two-IMU batches)."""

    @property
    def rate_hz(self) -> float:
        """The sample rate it navigates at, Hz."""
        ...

    def process(self, batch: BatchT_contra) -> NavBatch | None:
        """Estimates for the batch's samples (None while there are none yet)."""
        ...

    def retime(self, rate_hz: float) -> None:
        """Navigate at ``rate_hz`` (the unit's clock has told it), before the first sample."""
        ...


class AidedNavigator(Protocol):
    """A navigator that also takes ToF ranges and barometer readings
    (``footnav.pipeline.navigation.navigator.Navigator``)."""

    def add_ranges(self, batch: RangeBatch) -> None: ...

    def add_pressure(self, batch: PressureBatch) -> None: ...


async def run_pipeline(
    source: AsyncIterator[Any],
    navigator: BatchNavigator[B],
    sinks: Sequence[NavSink],
    queue_batches: int = 256,
) -> None:
    """Run until ``source`` is exhausted; every batch reaches the navigator, every estimate every sink.
    A navigator with a ``bind_sinks(sinks)`` method is given the sinks and hands its estimates to them
    itself, when it has made them (two feet in lockstep: ``footnav.pipeline.two_feet.live``).

    Raises whatever the source, navigator or a sink raised (the other stage is cancelled).
    """
    queue: asyncio.Queue[Any] = asyncio.Queue(maxsize=queue_batches)
    bind = getattr(navigator, "bind_sinks", None)
    if bind is not None:  # it hands its estimates to the sinks itself (footnav.pipeline.two_feet.live)
        bind(sinks)

    async def produce() -> None:
        async for batch in source:
            await queue.put(batch)
        await queue.put(None)  # on an error the TaskGroup cancels the consumer instead

    async def estimate() -> None:
        while (batch := await queue.get()) is not None:
            if isinstance(batch, RangeBatch):  # only sources of a navigator that takes them yield these
                cast(AidedNavigator, navigator).add_ranges(batch)
                continue
            if isinstance(batch, PressureBatch):
                cast(AidedNavigator, navigator).add_pressure(batch)
                continue
            nav = navigator.process(batch)
            if nav is not None:
                for sink in sinks:
                    sink(nav)

    async with asyncio.TaskGroup() as tg:
        tg.create_task(produce())
        tg.create_task(estimate())
