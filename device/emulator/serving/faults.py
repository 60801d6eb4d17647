"""Wire faults for the emulated unit: bit errors, dropped, duplicated and reordered packets.

A :class:`FaultInjector` rewrites the bytes the emulated firmware hands to its transport, one data
packet at a time (``AA hi lo N payload chk`` frames; command ACKs pass untouched), and logs what it
did by package number so a test can account for every packet the host did or did not get. Stalls,
partial writes, garbage between packets and unplugging are properties of the transport
(:class:`footnav.device.emulator.serving.pty.PtyShoeServer`), not of the byte content, and live there.

The faults are independent per packet, in this order: drop (p_drop); else duplicate (p_dup, the copy
follows at once); else hold back behind the next packet (p_reorder, a swap with its successor); then
each bit of each copy is flipped with probability ``bit_error_rate`` (a binary symmetric channel).
A single flipped bit always breaks the packet's 16-bit additive checksum (it changes the sum by
±2^k, k < 8); two flips of the same bit position in two bytes, one up and one down, cancel, so a
corrupted packet can pass the checksum (about 0.5 % of the corrupted packets at a bit error rate of
1e-3, see ``benchmarks/integrity.py``). The log records every corrupted copy all the same.
``renumber`` gives chosen packets another number with a checksum that matches (the worst case of a
cancelling pair, made on purpose). :meth:`FaultInjector.apply_frames` returns the frames as cut
before the bit errors, so the transport can put garbage between them even where a flip hit a header.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_DATA, _ACK = 0xAA, 0xA0


@dataclass(frozen=True, slots=True)
class WireFaults:
    """Fault rates; all zero is a perfect wire.

    Attributes
    ----------
    bit_error_rate
        probability that any one bit of a data packet is flipped.
    drop_rate
        probability that a data packet is not sent.
    duplicate_rate
        probability that a data packet is sent twice in a row.
    reorder_rate
        probability that a data packet is sent after the one that follows it.
    renumber
        ``(number, sent_as)`` pairs: the packet numbered ``number`` goes out numbered ``sent_as``
        (uint16), its checksum made to match; its first sending only (a lossless resend is clean).
    """

    bit_error_rate: float = 0.0
    drop_rate: float = 0.0
    duplicate_rate: float = 0.0
    reorder_rate: float = 0.0
    renumber: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        for name in ("bit_error_rate", "drop_rate", "duplicate_rate", "reorder_rate"):
            value = getattr(self, name)
            if not 0.0 <= value < 1.0:
                raise ValueError(f"{name} must be in [0, 1), got {value}")

    @property
    def any(self) -> bool:
        return any((self.bit_error_rate, self.drop_rate, self.duplicate_rate, self.reorder_rate, self.renumber))


@dataclass(slots=True)
class FaultLog:
    """What the injector did, by package number (uint16, as on the wire)."""

    packets_in: int = 0
    dropped: list[int] = field(default_factory=list)
    duplicated: list[int] = field(default_factory=list)
    reordered: list[int] = field(default_factory=list)
    """Numbers of packets sent after their successor."""
    corrupted: list[int] = field(default_factory=list)
    """Numbers of packets with at least one flipped bit (each corrupted copy once)."""
    bits_flipped: int = 0
    renumbered: list[int] = field(default_factory=list)
    """Numbers of packets sent with another number (``WireFaults.renumber``)."""
    undetected: list[int] = field(default_factory=list)
    """Numbers of corrupted copies whose checksum still matches (what the 16-bit sum misses)."""


def split_frames(data: bytes) -> list[bytes]:
    """Cut a firmware output chunk into its frames (data packets and 4-byte command ACKs).

    Raises
    ------
    ValueError
        the chunk is not a sequence of whole frames (the firmware never writes one).
    """
    frames: list[bytes] = []
    i, n = 0, len(data)
    while i < n:
        head = data[i]
        if head == _DATA and i + 4 <= n:
            size = data[i + 3] + 6
        elif head == _ACK:
            size = 4
        else:
            raise ValueError(f"byte {i} of a firmware chunk (0x{head:02X}) does not start a frame")
        if i + size > n:
            raise ValueError(f"frame at byte {i} runs past the end of the chunk")
        frames.append(data[i : i + size])
        i += size
    return frames


class FaultInjector:
    """Applies :class:`WireFaults` to firmware output chunks, seeded and logged.

    Parameters
    ----------
    faults
        the rates.
    seed
        seed of the random generator (the same seed and input give the same output).
    """

    def __init__(self, faults: WireFaults, seed: int = 0) -> None:
        self.faults = faults
        self.log = FaultLog()
        self._rng = np.random.default_rng(seed)
        self._held: bytes | None = None
        self._renumber = dict(faults.renumber)

    def apply(self, chunk: bytes) -> tuple[bytes, int]:
        """The bytes to send for one firmware output chunk, and the number of data packets in them.

        A packet held back for reordering at the end of a chunk goes out after the first packet of
        the next chunk (or at :meth:`flush`).
        """
        frames, n_data = self.apply_frames(chunk)
        return b"".join(f for f, _ in frames), n_data

    def apply_frames(self, chunk: bytes) -> tuple[list[tuple[bytes, bool]], int]:
        """As :meth:`apply`, the frames kept apart: ``(bytes, is_data_packet)`` each, in wire order."""
        f, rng, log = self.faults, self._rng, self.log
        out: list[tuple[bytes, bool]] = []
        sent_before = len(log.dropped), len(log.duplicated), log.packets_in, self._held is not None
        for made in split_frames(chunk):
            if made[0] != _DATA:
                out.append((made, False))
                continue
            log.packets_in += 1
            number = made[1] << 8 | made[2]
            frame = made
            if number in self._renumber:  # once: a lossless resend goes out as it should
                frame = _renumbered(made, self._renumber.pop(number))
                log.renumbered.append(number)
            if f.drop_rate and rng.random() < f.drop_rate:
                log.dropped.append(number)
                continue
            copies = [frame]
            if f.duplicate_rate and rng.random() < f.duplicate_rate:
                log.duplicated.append(number)
                copies.append(frame)
            copies = [self._flip_bits(c, number) for c in copies]
            if self._held is not None:  # the held packet follows this one
                out.extend((c, True) for c in copies)
                out.append((self._held, True))
                self._held = None
                continue
            if f.reorder_rate and len(copies) == 1 and rng.random() < f.reorder_rate:
                log.reordered.append(number)
                self._held = copies[0]
                continue
            out.extend((c, True) for c in copies)
        dropped, duplicated, packets_in, held_before = sent_before
        n_data = (
            (log.packets_in - packets_in)
            - (len(log.dropped) - dropped)
            + (len(log.duplicated) - duplicated)
            + int(held_before)
            - int(self._held is not None)
        )
        return out, n_data

    def flush(self) -> bytes:
        """A packet still held back for reordering (the stream ended after it), else b""."""
        held, self._held = self._held, None
        return held or b""

    def _flip_bits(self, frame: bytes, number: int) -> bytes:
        ber = self.faults.bit_error_rate
        if not ber:
            return frame
        n_bits = 8 * len(frame)
        flips = int(self._rng.binomial(n_bits, ber))
        if flips == 0:
            return frame
        where = self._rng.choice(n_bits, size=flips, replace=False)
        buf = bytearray(frame)
        for bit in where:
            buf[bit >> 3] ^= 1 << (bit & 7)
        self.log.corrupted.append(number)
        self.log.bits_flipped += flips
        if sum(buf[:-2]) & 0xFFFF == (buf[-2] << 8 | buf[-1]):
            self.log.undetected.append(number)
        return bytes(buf)


def _renumbered(frame: bytes, number: int) -> bytes:
    """``frame`` numbered ``number`` (uint16), its checksum recomputed."""
    buf = bytearray(frame)
    buf[1], buf[2] = (number >> 8) & 0xFF, number & 0xFF
    chk = sum(buf[:-2]) & 0xFFFF
    buf[-2], buf[-1] = chk >> 8, chk & 0xFF
    return bytes(buf)
