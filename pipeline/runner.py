"""The stage runner: samples in, estimates out to every sink, over bounded asyncio queues.

    source ──▶ [queue] ──▶ navigator ──▶ sinks (callables, each must return quickly)

The queue is bounded, so a slow estimator pushes back on the source (the OS and the unit buffer the
bytes; the capture, written by the source, never drops anything). Sinks must not block: the Rerun
logger, for example, only enqueues for its own thread. This is the only module of ``pipeline`` that
knows asyncio.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable, Sequence
from typing import Protocol, TypeVar

from pipeline.nav_types import NavBatch

NavSink = Callable[[NavBatch], object]  # return values are ignored

BatchT_contra = TypeVar("BatchT_contra", contravariant=True)
B = TypeVar("B")


class BatchNavigator(Protocol[BatchT_contra]):
    """What the runner drives: ``pipeline.navigator.Navigator`` (``ImuBatch``) or
    ``pipeline.dual_navigator.DualNavigator`` (two-IMU batches)."""

    def process(self, batch: BatchT_contra) -> NavBatch | None:
        """Estimates for the batch's samples (None while there are none yet)."""
        ...


async def run_pipeline(
    source: AsyncIterator[B],
    navigator: BatchNavigator[B],
    sinks: Sequence[NavSink],
    queue_batches: int = 256,
) -> None:
    """Run until ``source`` is exhausted; every batch reaches the navigator, every estimate every sink.

    Raises whatever the source, navigator or a sink raised (the other stage is cancelled).
    """
    queue: asyncio.Queue[B | None] = asyncio.Queue(maxsize=queue_batches)

    async def produce() -> None:
        async for batch in source:
            await queue.put(batch)
        await queue.put(None)  # on an error the TaskGroup cancels the consumer instead

    async def estimate() -> None:
        while (batch := await queue.get()) is not None:
            nav = navigator.process(batch)
            if nav is not None:
                for sink in sinks:
                    sink(nav)

    async with asyncio.TaskGroup() as tg:
        tg.create_task(produce())
        tg.create_task(estimate())
