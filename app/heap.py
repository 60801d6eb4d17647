"""Keep the native heap of a long session compact (glibc only; elsewhere these do nothing).

A live session allocates and frees buffers on several threads at once: the Rerun SDK's encoder and
sink threads, the capture's compressor thread and the event loop. glibc's allocator gives each
thread that contends for the heap an arena of its own (up to 8 per core) and returns freed memory
from an arena's interior to the system only when ``malloc_trim`` walks it (glibc ≥ 2.8; ``free``
only trims an arena's top). Over an hour the freed but unreturned pages add up, so the resident size
creeps although Python's own heap is flat (``tracemalloc``; ``benchmarks/soak.py``).

Two remedies, both from glibc's documented interface (``mallopt(3)``, ``malloc_trim(3)``):
``limit_arenas`` caps the number of arenas before the session's threads start, and
:func:`trim_periodically` returns free pages to the system every ``period_s``.
"""

from __future__ import annotations

import asyncio
import ctypes
import ctypes.util
import functools
import logging

log = logging.getLogger(__name__)

M_ARENA_MAX = -8  # glibc malloc.h
DEFAULT_ARENAS = 2
DEFAULT_TRIM_PERIOD_S = 10.0


@functools.cache
def _libc() -> ctypes.CDLL | None:
    """The C library if it is glibc (it has ``malloc_trim``), else None."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name)
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
        libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    except (OSError, AttributeError, TypeError):
        log.debug("not glibc: the native heap is left to the platform's allocator")
        return None
    return libc


def limit_arenas(arenas: int = DEFAULT_ARENAS) -> bool:
    """Cap glibc's malloc arenas; call before the session starts its threads. True if applied."""
    libc = _libc()
    return libc is not None and libc.mallopt(M_ARENA_MAX, arenas) == 1


def trim() -> bool:
    """Return the free pages of every arena to the system. True if glibc released memory."""
    libc = _libc()
    return libc is not None and libc.malloc_trim(0) == 1


async def trim_periodically(period_s: float = DEFAULT_TRIM_PERIOD_S) -> None:
    """:func:`trim` every ``period_s`` until cancelled (a few ms each, off the event loop)."""
    if _libc() is None:
        return
    while True:
        await asyncio.sleep(period_s)
        await asyncio.to_thread(trim)
