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

import dataclasses
import functools
import re
from collections.abc import Iterable
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
    """(m, N) payload bytes (a view of one copy of the bytes read)."""
    heads: NDArray[np.int64] | None = None
    """(m,) the first four payload bytes of each packet as a big-endian uint32 (the 64 MHz time stamp of
    every output that carries one), when N >= 4."""

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


@dataclasses.dataclass(slots=True)
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

    def checkpoint(self) -> tuple[bytes, FramerStats]:
        """The framer's state, for :meth:`rewind`."""
        return bytes(self._buf), dataclasses.replace(self.stats)

    def rewind(self, point: tuple[bytes, FramerStats]) -> None:
        """Back to the state of :meth:`checkpoint` ``point``, as if nothing had been fed since."""
        self._buf[:] = point[0]
        for name in FramerStats.__dataclass_fields__:
            setattr(self.stats, name, getattr(point[1], name))

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        """Add received bytes; return the frames they complete, in stream order."""
        out: list[Frame] = []
        for item in self.feed_runs(data):
            if type(item) is PacketRun:
                out.extend(item.packets())
            else:
                out.append(item)  # type: ignore[arg-type]
        return out

    def feed_runs(
        self, data: bytes | bytearray | memoryview, starts: list[int] | None = None
    ) -> list[Frame | PacketRun]:
        """As :meth:`feed`, with stretches of same-length valid packets returned as one :class:`PacketRun`.

        A stream of one packet kind then costs a few numpy operations per read instead of a Python
        iteration per packet; the first invalid packet ends a run and is handled byte by byte.
        ``starts``, if given, gets the offset in ``data`` of each returned frame's first byte (negative:
        it began in bytes held from an earlier call).
        """
        buf = self._buf
        held = len(buf)
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
                            if starts is not None:
                                starts.append(i - held)
                            n_packets += len(run)
                            i += len(run) * (length + 6)
                            continue
                    end = i + length + 4
                    if end + 2 > n:
                        break
                    if sum(buf[i:end]) & 0xFFFF == (buf[end] << 8 | buf[end + 1]):
                        append(DataPacket(buf[i + 1] << 8 | buf[i + 2], bytes(buf[i + 4 : end])))
                        if starts is not None:
                            starts.append(i - held)
                        n_packets += 1
                        i = end + 2
                        continue
                    stats.checksum_errors += 1
            elif head == ACK_HEADER:
                if n - i < 4:
                    break
                if (buf[i + 2] << 8 | buf[i + 3]) == ACK_HEADER + buf[i + 1]:
                    append(DeviceAck(buf[i + 1]))
                    if starts is not None:
                        starts.append(i - held)
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


def split_by_read(
    frames: list[Frame | PacketRun], starts: list[int], read_ends: NDArray[np.int64]
) -> list[list[Frame | PacketRun]]:
    """``frames`` of one :meth:`Framer.feed_runs` call over several reads joined, as each read alone would
    have completed them: per read, the frames whose last byte it holds (a run split where a read ends).

    Parameters
    ----------
    frames, starts
        the frames and their first bytes' offsets in the joined bytes (``feed_runs(joined, starts)``).
    read_ends
        (r,) offset in the joined bytes just after each read's last byte, increasing.

    Returns
    -------
    list[list[Frame | PacketRun]]
        r lists, in stream order.
    """
    out: list[list[Frame | PacketRun]] = [[] for _ in range(len(read_ends))]
    for frame, start in zip(frames, starts, strict=True):
        if type(frame) is PacketRun:
            ends = packet_ends(frame, start)
            read_of = np.searchsorted(read_ends, ends)
            cuts = np.flatnonzero(np.diff(read_of)) + 1
            for a, b in zip([0, *cuts.tolist()], [*cuts.tolist(), len(frame)], strict=True):
                heads = None if frame.heads is None else frame.heads[a:b]
                out[int(read_of[a])].append(PacketRun(frame.numbers[a:b], frame.payloads[a:b], heads))
        else:
            size = 4 if type(frame) is DeviceAck else len(frame.payload) + PACKET_OVERHEAD  # type: ignore[union-attr]
            out[int(np.searchsorted(read_ends, start + size))].append(frame)
    return out


def packet_ends(run: PacketRun, start: int) -> NDArray[np.int64]:
    """(m,) offset just after each packet of ``run``, which begins at offset ``start``."""
    stride = int(run.payloads.shape[1]) + PACKET_OVERHEAD
    return start + stride * np.arange(1, len(run) + 1, dtype=np.int64)


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
    :data:`_MIN_RUN` of them; else None (the caller goes on byte by byte).

    Each window takes one matrix product with :func:`_run_weights`: per packet a code that is valid only for
    a valid packet, its number and its head."""
    stride = length + 6
    available = (len(buf) - start) // stride
    weights, valid_code = _run_weights(length)
    fields: list[NDArray[np.int64]] = []
    payloads: list[NDArray[np.uint8]] = []
    taken = 0
    while taken < available:
        k = min(_RUN_WINDOW, available - taken)
        at = start + taken * stride
        rows = np.frombuffer(buf[at : at + k * stride], dtype=np.uint8).reshape(k, stride)  # a copy of the bytes
        r = np.dot(rows.astype(np.float64), weights)  # (k, 3): code, number, head; exact in float64
        code = r[:, 0]
        if length > _NO_CARRY_LENGTH:  # the byte sum may exceed 2**16 by one carry
            code = np.where(code == valid_code + _CODE_SCALE * (1 << 16), valid_code, code)
        valid = code == valid_code
        good = k if np.count_nonzero(valid) == k else int(np.argmin(valid))
        fields.append(r[:good, 1:].astype(np.int64))
        payloads.append(rows[:good, 4 : 4 + length])
        taken += good
        if good < k:
            break
    if taken < _MIN_RUN:
        return None
    f = fields[0] if len(fields) == 1 else np.concatenate(fields)
    return PacketRun(
        f[:, 0], payloads[0] if len(payloads) == 1 else np.concatenate(payloads), f[:, 1] if length >= 4 else None
    )


_NO_CARRY_LENGTH: Final = 252
"""Up to this payload length the sum of header and payload bytes, at most (N + 4)·255, is below 2**16."""
_CODE_SCALE: Final = float(1 << 18)
"""Weight of the checksum difference in a packet's code: above any header difference (< 2**16)."""


@functools.cache
def _run_weights(length: int) -> tuple[NDArray[np.float64], float]:
    """Weights (N + 6, 3) that turn the bytes of a packet of payload ``length`` N into its code, number and
    head, and the code of a valid one.

    code = 2**18·(sum of bytes AA .. last payload byte - checksum) + 256·byte 0 + byte 3, which equals
    256·0xAA + N exactly when the checksum matches (for N <= :data:`_NO_CARRY_LENGTH`; beyond, the sum
    may also be the checksum + 2**16) and the header is AA with length N: the checksum term is 0 or at
    least 2**18 in size, the header term below 2**16. number = 256·byte 1 + byte 2; head = bytes 4..7
    as a big-endian integer (the first min(N, 4) payload bytes). Every value is an integer below 2**35,
    exact in float64.
    """
    w = np.zeros((length + 6, 3))
    w[: length + 4, 0] = _CODE_SCALE
    w[length + 4 :, 0] = (-256.0 * _CODE_SCALE, -_CODE_SCALE)
    w[(0, 3), 0] += (256.0, 1.0)
    w[(1, 2), 1] = (256.0, 1.0)
    head = min(length, 4)
    w[4 : 4 + head, 2] = 256.0 ** np.arange(head - 1, -1, -1)
    return w, PACKET_HEADER * 256.0 + length
