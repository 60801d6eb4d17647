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


Frame = DataPacket | DeviceAck


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

    Args:
        accepted_lengths: payload lengths N that can occur; any other N marks a false header and is
            skipped at once instead of waiting for N + 6 bytes. None accepts 0..255.
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
        buf = self._buf
        buf += data
        n = len(buf)
        accepted = self._accepted
        stats = self.stats
        out: list[Frame] = []
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
