"""The byte link a unit driver reads and writes: the interface every transport implements.

Serial (:mod:`footnav.device.links.serial`), BLE (:mod:`footnav.device.links.ble`), the reconnecting
wrapper (:mod:`footnav.device.links.reconnecting`) and a capture's replay
(:class:`footnav.device.links.replay.CaptureReplayLink`) are each a :class:`ByteLink`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal, Protocol

CaptureTap = Callable[[Literal["rx", "tx"], int, bytes], None]
"""``tap(direction, host_ns, data)``: sees every byte read or written, before any decoding."""


class ByteLink(Protocol):
    """What a unit needs from a transport (serial, BLE, TCP, replay)."""

    @property
    def name(self) -> str:
        """Port or address, for messages."""
        ...

    async def read(self) -> bytes:
        """Next bytes (at least one), ``b""`` after close; raise ``DeviceError`` on disconnect."""
        ...

    async def write(self, data: bytes) -> None:
        """Send bytes; raise ``DeviceError`` on failure."""
        ...

    async def close(self) -> None:
        """Release the transport (idempotent)."""
        ...


class StampedByteLink(ByteLink, Protocol):
    """A link whose reads carry their own host time (a replay: the time each read had live). The unit driver
    then takes those stamps instead of ``time.monotonic_ns()`` after each read."""

    async def read_stamped(self) -> list[tuple[bytes, int]]:
        """One or more consecutive reads, each with its host time (``time.monotonic_ns()`` scale, ns); []
        after close."""
        ...
