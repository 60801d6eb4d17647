"""Replay of a capture's bytes: one unit's device -> host reads played back as a :class:`ByteLink`.

The unit driver reads a replay link as it reads a live port, so a replay frames, orders and decodes
the captured bytes exactly as the live session did (the capture format:
:mod:`footnav.device.files.capture`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from footnav.device.files.capture import CaptureInfo, CaptureMessage, ReadState, iter_capture
from footnav.device.files.capture_records import Gap
from footnav.pipeline.errors import InputFormatError


@dataclass(frozen=True, slots=True)
class LostStretch:
    """A damaged stretch of a capture as one unit's replay met it.

    Attributes
    ----------
    gap
        the file offsets skipped.
    before_ns, after_ns
        host time (``time.monotonic_ns()`` as captured) of the unit's last read before the stretch
        and its first read after it (None: none before, or the capture ended).
    """

    gap: Gap
    before_ns: int | None
    after_ns: int | None

    @property
    def seconds(self) -> float | None:
        """How long the unit's stream went without a read across the stretch, s (None: unknown)."""
        if self.before_ns is None or self.after_ns is None:
            return None
        return (self.after_ns - self.before_ns) / 1e9


JOIN_BYTES = 65536
"""At full speed :meth:`CaptureReplayLink.read_stamped` returns captured reads up to about this many bytes at
once (about 2 s of a 1 kHz IMU stream)."""


class CaptureReplayLink:
    """A :class:`footnav.device.links.base.StampedByteLink` that returns one unit's captured device -> host
    bytes with the host time each read had live, so the unit driver frames and batches them exactly as it
    did live and replayed estimates carry the live session's ``host_ns``.

    :meth:`read_stamped` returns one captured read, or at full speed as many as follow each other up to
    :data:`JOIN_BYTES` and the next host write (the driver decodes them in one pass, each packet stamped
    with its own read's time; what the unit answered to a command comes after the driver has sent it).

    Parameters
    ----------
    path
        the capture.
    foot
        which unit.
    speed
        1.0 = the captured pace, N = N times faster, ``math.inf`` = as fast as possible.
    paced
        False returns reads at once until :attr:`paced` is set (a replay window's lead-in: decoded, not navigated, not
        waited for).
    clock_origin
        ``(monotonic_ns at replay start, captured ns at replay start)`` shared by all feet of one replay so they stay in
        step; default: set at the first read.
    on_progress
        called with (bytes read, file size) now and then.
    """

    def __init__(
        self,
        path: Path,
        foot: str,
        *,
        speed: float = 1.0,
        paced: bool = True,
        clock_origin: list[int] | None = None,
        on_progress: Callable[[int, int], None] | None = None,
    ) -> None:
        self.path = Path(path)
        self.foot = foot
        self.speed = speed
        self.paced = paced
        self.state = ReadState()
        self.events: list[dict[str, Any]] = []
        """Events of this unit met so far (JSON objects)."""
        self.reads = 0
        self.lost: list[LostStretch] = []
        """Damaged stretches skipped between this unit's reads (the replay resumed after each)."""
        self._gaps_seen = 0
        self._last_ns: int | None = None
        self._origin = clock_origin if clock_origin is not None else []
        self._on_progress = on_progress
        self._it = iter_capture(self.path, self.state)
        self._ahead: CaptureMessage | None = None  # a read taken past a host write, returned next
        self._closed = False
        self.writes: list[bytes] = []
        """Bytes the host wrote during the replay (nothing is sent anywhere)."""

    @property
    def name(self) -> str:
        return f"{self.path.name} [{self.foot}]"

    def _next_rx(self) -> tuple[CaptureMessage | None, bool]:
        """The next captured read of this unit (None at the end), and whether the host wrote to the unit
        after the read before it."""
        if self._ahead is not None:
            ahead, self._ahead = self._ahead, None
            return ahead, True
        wrote = False
        for item in self._it:
            if isinstance(item, CaptureInfo):
                if self.foot not in item.feet:
                    known = ", ".join(item.feet) or "none"
                    raise InputFormatError(f"{self.path} has no unit {self.foot!r} (units: {known})")
                continue
            if item.foot != self.foot:
                continue
            if item.direction == "events":
                with contextlib.suppress(json.JSONDecodeError):
                    self.events.append(json.loads(item.data))
                continue
            if item.direction != "rx":
                wrote = True
                continue
            self._note_gaps(item.host_ns)
            self._last_ns = item.host_ns
            return item, wrote
        self._note_gaps(None)
        return None, wrote

    def _note_gaps(self, after_ns: int | None) -> None:
        for gap in self.state.gaps[self._gaps_seen :]:
            self.lost.append(LostStretch(gap, self._last_ns, after_ns))
        self._gaps_seen = len(self.state.gaps)

    async def read(self) -> bytes:
        """The bytes of :meth:`read_stamped`; ``b""`` at the end of the capture or the window."""
        return b"".join(data for data, _ in await self.read_stamped())

    async def read_stamped(self) -> list[tuple[bytes, int]]:
        """The next captured read and its captured host time (ns), paced by :attr:`speed` (not in a window's
        lead-in); at full speed the reads that follow it too, up to :data:`JOIN_BYTES` in all and up to the
        next host write; [] at the end of the capture or the window."""
        if self._closed:
            return []
        item, _ = self._next_rx()
        if item is None:
            self._closed = True
            return []
        if self.paced and not self._origin:
            self._origin[:] = [time.monotonic_ns(), item.host_ns]
        reads = [(item.data, item.host_ns)]
        if self.speed == float("inf"):
            size = len(item.data)
            while size < JOIN_BYTES:
                more, wrote = self._next_rx()
                if more is None:
                    break
                if wrote:  # live, the driver had sent a command before this read: it goes after that
                    self._ahead = more
                    break
                reads.append((more.data, more.host_ns))
                size += len(more.data)
            await asyncio.sleep(0)  # let the other foot and the sinks run
        elif self.paced:
            due_ns = self._origin[0] + (item.host_ns - self._origin[1]) / self.speed
            delay = (due_ns - time.monotonic_ns()) / 1e9
            if delay > 0:
                await asyncio.sleep(delay)
        before = self.reads
        self.reads += len(reads)
        if self._on_progress is not None and self.reads // 256 != before // 256:
            self._on_progress(self.state.bytes_read, self.state.size)
        return reads

    async def write(self, data: bytes) -> None:
        """Commands go nowhere in a replay; kept for inspection."""
        self.writes.append(bytes(data))

    async def close(self) -> None:
        self._closed = True
        with contextlib.suppress(Exception):
            self._it.close()  # type: ignore[attr-defined]
