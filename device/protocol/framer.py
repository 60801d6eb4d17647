"""Sans-I/O framer for the OpenShoe device -> host byte stream: data packets and command ACKs.

Frames (protocol-openshoe.md sections 0, 4.1 and 10)::

    data packet  AA pkt_hi pkt_lo N payload[N] chk_hi chk_lo   chk = sum(AA .. last payload byte) mod 2**16
    command ACK  A0 cmd chk_hi chk_lo                          chk = 0xA0 + cmd

A read may hold part of a frame or several. :meth:`Framer.feed` keeps the tail, validates every
candidate by checksum, and on failure advances one byte and searches for the next header byte, so it
resynchronises after any corruption. 0xAA and 0xA0 occur inside payloads too; only the checksum
decides. Source: ``hcarlsso/openshoe-framework:src/external_interfaces/external_interface.c``
(``assemble_output_data``).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

PACKET_HEADER: Final = 0xAA
ACK_HEADER: Final = 0xA0
PACKET_OVERHEAD: Final = 6
"""Header (4) + checksum (2) bytes around a data packet's payload."""

_HEADER_RE: Final = re.compile(b"[\xa0\xaa]")


class DataPacket(NamedTuple):
    """A checksum-valid data packet."""

    number: int
    """Package number, uint16 as sent (one counter per interface, wraps at 65535)."""
    payload: bytes


class DeviceAck(NamedTuple):
    """A checksum-valid ACK of a host command."""

    cmd_id: int


class PacketRun(NamedTuple):
    """Consecutive checksum-valid data packets of one payload length, found in one vectorised pass."""

    numbers: NDArray[np.int64]
    """(m,) package numbers, uint16 as sent."""
    payloads: NDArray[np.uint8]
    """(m, N) payload bytes (a read-only view of one buffer)."""

    def __len__(self) -> int:
        return int(self.numbers.shape[0])

    def packets(self) -> list[DataPacket]:
        """The run as single packets."""
        return [DataPacket(int(k), row.tobytes()) for k, row in zip(self.numbers, self.payloads, strict=True)]


Frame = DataPacket | DeviceAck

_MIN_RUN: Final = 8
"""Look for a run when at least this many packets of the current length could follow."""
_RUN_WINDOW: Final = 512
"""Packets checked per vectorised step (the copy made per step is this many packets at most)."""


@dataclass(slots=True)
class FramerStats:
    """Running counts since the framer was created."""

    packets: int = 0
    """Valid data packets returned."""
    acks: int = 0
    """Valid device ACKs returned."""
    bytes_skipped: int = 0
    """Bytes discarded because they belonged to no valid frame (corruption, garbage, stale tails)."""
    checksum_errors: int = 0
    """Candidate data packets (header and an accepted length) whose checksum did not match."""
    bad_lengths: int = 0
    """Candidate data packets rejected because N was not in ``accepted_lengths``."""


class Framer:
    """Finds data packets and device ACKs in a byte stream, resynchronising byte by byte.

    Parameters
    ----------
    accepted_lengths
        payload lengths N that can occur; any other N marks a false header and is skipped at once instead of waiting for
        N + 6 bytes. None accepts 0..255.
    """

    def __init__(self, accepted_lengths: Iterable[int] | None = None) -> None:
        self._buf = bytearray()
        self._accepted = None if accepted_lengths is None else frozenset(accepted_lengths)
        self.stats = FramerStats()

    @property
    def buffered(self) -> int:
        """Bytes held back as the possible start of a frame."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        """Add received bytes; return the frames they complete, in stream order."""
        out: list[Frame] = []
        for item in self.feed_runs(data):
            if type(item) is PacketRun:
                out.extend(item.packets())
            else:
                out.append(item)  # type: ignore[arg-type]
        return out

    def feed_runs(self, data: bytes | bytearray | memoryview) -> list[Frame | PacketRun]:
        """As :meth:`feed`, with stretches of same-length valid packets returned as one :class:`PacketRun`.

        A stream of one packet kind then costs a few numpy operations per read instead of a Python
        iteration per packet; the first invalid packet ends a run and is handled byte by byte.
        """
        buf = self._buf
        buf += data
        n = len(buf)
        accepted = self._accepted
        stats = self.stats
        out: list[Frame | PacketRun] = []
        append = out.append
        search = _HEADER_RE.search
        i = 0
        n_packets = 0
        while i < n:
            head = buf[i]
            if head == PACKET_HEADER:
                if n - i < 4:
                    break
                length = buf[i + 3]
                if accepted is not None and length not in accepted:
                    stats.bad_lengths += 1
                else:
                    if n - i >= _MIN_RUN * (length + 6):
                        run = _run_at(buf, i, length)
                        if run is not None:
                            append(run)
                            n_packets += len(run)
                            i += len(run) * (length + 6)
                            continue
                    end = i + length + 4
                    if end + 2 > n:
                        break
                    if sum(buf[i:end]) & 0xFFFF == (buf[end] << 8 | buf[end + 1]):
                        append(DataPacket(buf[i + 1] << 8 | buf[i + 2], bytes(buf[i + 4 : end])))
                        n_packets += 1
                        i = end + 2
                        continue
                    stats.checksum_errors += 1
            elif head == ACK_HEADER:
                if n - i < 4:
                    break
                if (buf[i + 2] << 8 | buf[i + 3]) == ACK_HEADER + buf[i + 1]:
                    append(DeviceAck(buf[i + 1]))
                    stats.acks += 1
                    i += 4
                    continue
            # Not a valid frame at i: skip to the next header byte after it.
            m = search(buf, i + 1)
            j = n if m is None else m.start()
            stats.bytes_skipped += j - i
            i = j
        stats.packets += n_packets
        del buf[:i]
        return out


def data_numbers(frames: list[Frame | PacketRun]) -> tuple[NDArray[np.int64], int | None]:
    """The package numbers (m,) of the data packets among ``frames``, in order (runs are not split into
    packets), and the payload length of the last one (None when there is none)."""
    parts: list[NDArray[np.int64]] = []
    length: int | None = None
    for f in frames:
        if type(f) is PacketRun:
            parts.append(f.numbers)
            length = int(f.payloads.shape[1])
        elif type(f) is DataPacket:
            parts.append(np.array([f.number], dtype=np.int64))
            length = len(f.payload)
    return (np.concatenate(parts) if parts else np.empty(0, dtype=np.int64)), length


def _run_at(buf: bytearray, start: int, length: int) -> PacketRun | None:
    """The valid packets of payload ``length`` back to back from ``buf[start]``, if there are at least
    :data:`_MIN_RUN` of them; else None (the caller goes on byte by byte)."""
    stride = length + 6
    available = (len(buf) - start) // stride
    numbers: list[NDArray[np.int64]] = []
    payloads: list[NDArray[np.uint8]] = []
    taken = 0
    while taken < available:
        k = min(_RUN_WINDOW, available - taken)
        at = start + taken * stride
        rows = np.frombuffer(bytes(buf[at : at + k * stride]), dtype=np.uint8).reshape(k, stride)
        chk = rows[:, : length + 4].sum(axis=1, dtype=np.uint32) & 0xFFFF
        valid = (
            (rows[:, 0] == PACKET_HEADER)
            & (rows[:, 3] == length)
            & (chk == (rows[:, length + 4].astype(np.uint32) << 8 | rows[:, length + 5]))
        )
        good = k if bool(valid.all()) else int(np.argmin(valid))
        numbers.append(rows[:good, 1].astype(np.int64) << 8 | rows[:good, 2])
        payloads.append(rows[:good, 4 : 4 + length])
        taken += good
        if good < k:
            break
    if taken < _MIN_RUN:
        return None
    if len(numbers) == 1:
        return PacketRun(numbers[0], payloads[0])
    return PacketRun(np.concatenate(numbers), np.concatenate(payloads))
