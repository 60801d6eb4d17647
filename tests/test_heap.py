"""The native-heap trimming of long sessions (app/heap.py) returns freed memory to the system."""

from __future__ import annotations

import asyncio
import threading

import pytest
from footnav.app import heap

pytestmark = pytest.mark.skipif(heap._libc() is None, reason="the C library is not glibc: nothing to trim")


def _rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    raise AssertionError("no VmRSS in /proc/self/status")


def test_trim_returns_a_threads_freed_blocks_to_the_system() -> None:
    kept: list[bytearray] = []

    def churn() -> None:  # 180 MB in blocks below glibc's mmap threshold, freed but the last
        blocks = [bytearray(60_000) for _ in range(3_000)]
        kept.append(blocks[-1])

    worker = threading.Thread(target=churn)
    worker.start()
    worker.join()
    before = _rss_mb()
    assert heap.trim()
    assert before - _rss_mb() > 100.0


def test_periodic_trim_runs_until_cancelled() -> None:
    async def session() -> None:
        trimmer = asyncio.create_task(heap.trim_periodically(period_s=0.01))
        await asyncio.sleep(0.1)
        assert not trimmer.done()
        trimmer.cancel()
        with pytest.raises(asyncio.CancelledError):
            await trimmer

    asyncio.run(session())
