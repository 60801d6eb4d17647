"""Decoding a unit's byte stream: framer, package numbers, plausibility and payloads, against a struct loop.

``python -m benchmarks.decode`` encodes an emulated 1 kHz walk (``footnav.device.emulator``: the demo's
rectangle, ``--seconds`` of it, 300 by default) as normal-IMU packets (0x40, 34 bytes each), cuts the
bytes into reads of ``--read-bytes`` (1024 by default: what a pseudo-terminal hands over, about 30
packets, as the reads of a two-feet capture) and times, best of ``--repeats`` by CPU time
(``time.process_time``, which other load on the machine disturbs less than the wall clock):

- **struct loop (baseline)**: per packet, the header and length test, ``sum`` of the bytes for the
  checksum and one ``struct.unpack_from``; per read, numpy arrays of the time stamps, specific force
  and angular rate;
- **OpenShoeUnit**: :class:`footnav.device.unit.OpenShoeUnit` reading the same chunks from an
  in-memory link: the framer, the package-number tracker, the plausibility guard, the payload
  decode, the shared tick clock and one ``ImuBatch`` per read, as ``footnav live`` and ``footnav
  replay`` run them;
- **OpenShoeUnit, wire faults**: the same with the emulator's fault injector on the bytes (``--ber``
  bit errors, ``--drops`` lost packets): the reads with a gap or a bad packet take the general path;
- **reads joined**: both again with the reads handed over as ``footnav replay --speed max`` does
  (:meth:`footnav.device.links.replay.CaptureReplayLink.read_stamped`: many reads per call, framed and,
  where clean, decoded in one pass);

in packets per second, with the ratio to the baseline measured in the same run. It then checks that
the unit delivered every packet of the clean stream once, in order, with the values and time stamps
the struct loop decoded (float32 values widened to float64, ticks unwrapped), and the same samples
with the reads joined.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import struct
import sys
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from benchmarks.machine import machine

TICK0 = 1_000_000
TICK_HZ = 64e6
_PACKET = struct.Struct(">BHBI6fH")  # AA, number, N, ts, ax ay az gx gy gz, checksum
PACKET_LEN = _PACKET.size


class ChunkLink:
    """A :class:`footnav.device.links.base.ByteLink` that ACKs each command and returns ``chunks``, one per read
    (no waiting: the decode alone is timed)."""

    def __init__(self, chunks: list[bytes]) -> None:
        from footnav.device.protocol.commands import CommandParser

        self._chunks = deque(chunks)
        self._answers: deque[bytes] = deque()
        self._parser = CommandParser()

    @property
    def name(self) -> str:
        return "memory"

    async def read(self) -> bytes:
        if self._answers:
            return self._answers.popleft()
        return self._chunks.popleft() if self._chunks else b""

    async def write(self, data: bytes) -> None:
        for cmd in self._parser.feed(data):
            chk = 0xA0 + cmd.cmd_id
            self._answers.append(bytes((0xA0, cmd.cmd_id, chk >> 8, chk & 0xFF)))

    async def close(self) -> None:
        self._chunks.clear()


class StampedChunkLink(ChunkLink):
    """:class:`ChunkLink` as a :class:`footnav.device.links.base.StampedByteLink`: the chunks as a replay at full
    speed hands them over, up to ``JOIN_BYTES`` per call, each stamped with its number."""

    def __init__(self, chunks: list[bytes]) -> None:
        super().__init__(chunks)
        self._stamp = 0

    async def read_stamped(self) -> list[tuple[bytes, int]]:
        from footnav.device.links.replay import JOIN_BYTES

        if self._answers:
            return [(self._answers.popleft(), self._stamp)]
        out: list[tuple[bytes, int]] = []
        size = 0
        while self._chunks and size < JOIN_BYTES:
            out.append((self._chunks.popleft(), self._stamp))
            size += len(out[-1][0])
            self._stamp += 1
        return out


@dataclass(frozen=True, slots=True)
class Decoded:
    """What one decoder delivered, concatenated over the reads."""

    counter: np.ndarray
    t_s: np.ndarray
    acc: np.ndarray
    gyr: np.ndarray


def stream(seconds: float) -> tuple[bytes, np.ndarray, np.ndarray, np.ndarray]:
    """Packets 1..n of the demo's walk at 1 kHz (ticks from :data:`TICK0`): the bytes, ticks, acc, gyr."""
    from footnav.device.emulator.motion.gait import simulate_walk
    from footnav.device.protocol.imu import encode_packets

    w = simulate_walk("rectangle", seconds, seed=1)
    n = len(w.t_s)
    ticks = (TICK0 + np.arange(n, dtype=np.int64) * 64_000) % (1 << 32)
    return encode_packets(np.arange(1, n + 1), ticks, w.acc_b_mps2, w.gyr_b_radps), ticks, w.acc_b_mps2, w.gyr_b_radps


def cut(data: bytes, read_bytes: int) -> list[bytes]:
    """``data`` in reads of ``read_bytes`` (the last one shorter)."""
    return [data[k : k + read_bytes] for k in range(0, len(data), read_bytes)]


def struct_loop(chunks: list[bytes]) -> Decoded:
    """The baseline: a plain per-packet ``struct.unpack_from`` decoder (no resynchronisation beyond one byte
    at a time, no package-number or plausibility checks, ticks unwrapped in Python)."""
    unpack = _PACKET.unpack_from
    buf = b""
    counters: list[np.ndarray] = []
    times: list[np.ndarray] = []
    accs: list[np.ndarray] = []
    gyrs: list[np.ndarray] = []
    last_tick: int | None = None
    total = 0
    for chunk in chunks:
        buf += chunk
        i, n = 0, len(buf)
        num: list[int] = []
        t: list[int] = []
        vals: list[tuple[float, ...]] = []
        while n - i >= PACKET_LEN:
            sync, number, length, ts, ax, ay, az, gx, gy, gz, chk = unpack(buf, i)
            if sync != 0xAA or length != 28 or sum(buf[i : i + PACKET_LEN - 2]) & 0xFFFF != chk:
                i += 1
                continue
            if last_tick is None:
                last_tick = total = ts
            total += (ts - last_tick) % (1 << 32)
            last_tick = ts
            num.append(number)
            t.append(total)
            vals.append((ax, ay, az, gx, gy, gz))
            i += PACKET_LEN
        buf = buf[i:]
        if num:
            v = np.array(vals, dtype=np.float64)
            counters.append(np.array(num, dtype=np.int64))
            times.append(np.array(t, dtype=np.int64) / TICK_HZ)
            accs.append(v[:, :3])
            gyrs.append(v[:, 3:])
    return Decoded(np.concatenate(counters), np.concatenate(times), np.concatenate(accs), np.concatenate(gyrs))


async def _unit_stream(chunks: list[bytes], spent: list[float], joined: bool) -> tuple[Decoded, object]:
    from footnav.device.modes import NormalImuMode
    from footnav.device.protocol.commands import CommandSet
    from footnav.device.unit import OpenShoeUnit
    from footnav.pipeline.samples import ImuBatch

    unit = OpenShoeUnit((StampedChunkLink if joined else ChunkLink)(chunks), command_set=CommandSet.V2015)
    await unit.start(NormalImuMode(0))
    batches: list[ImuBatch] = []
    c0 = time.process_time()
    async with contextlib.aclosing(unit.imu_batches()) as imu:
        async for batch in imu:
            batches.append(batch)
    spent.append(time.process_time() - c0)
    b = ImuBatch.concat(batches)
    return Decoded(b.counter, b.t_s, b.acc_b_mps2, b.gyr_b_radps), unit.stats


def unit_decode(chunks: list[bytes], joined: bool = False) -> tuple[Decoded, object, float]:
    """What :class:`footnav.device.unit.OpenShoeUnit` delivers from ``chunks`` (``joined``: handed over as a
    full-speed replay does), its link counts and the CPU time of the stream (after the start command's ACK), s."""
    spent: list[float] = []
    decoded, stats = asyncio.run(_unit_stream(chunks, spent, joined))
    return decoded, stats, spent[0]


def best_cpu(fn: Callable[[], float | None], repeats: int) -> float:
    """The least CPU time of ``repeats`` calls (``fn`` returns its own figure, or None to be timed whole)."""
    out = []
    for _ in range(repeats):
        c0 = time.process_time()
        own = fn()
        out.append(own if own is not None else time.process_time() - c0)
    return min(out)


def faulty(data: bytes, ber: float, drops: float) -> bytes:
    """``data`` through the emulator's fault injector (bit errors, dropped packets)."""
    from footnav.device.emulator.serving.faults import FaultInjector, WireFaults

    injector = FaultInjector(WireFaults(bit_error_rate=ber, drop_rate=drops), seed=3)
    step = PACKET_LEN * 100
    out = b"".join(injector.apply(data[k : k + step])[0] for k in range(0, len(data), step))
    return out + injector.flush()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.decode", description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=300.0, help="walk at 1 kHz (default 300: 300 000 packets)")
    ap.add_argument("--read-bytes", type=int, default=1024, help="bytes per read (default 1024)")
    ap.add_argument("--repeats", type=int, default=5, help="repeats per figure; the least CPU time counts (5)")
    ap.add_argument("--ber", type=float, default=1e-4, help="bit error rate of the faulty row (1e-4)")
    ap.add_argument("--drops", type=float, default=0.01, help="share of packets dropped in the faulty row (0.01)")
    args = ap.parse_args(argv)

    print("footnav stream decoding benchmark\n")
    for key, value in machine():
        print(f"  {key:22s} {value}")
    data, ticks, acc, gyr = stream(args.seconds)
    n = len(ticks)
    chunks = cut(data, args.read_bytes)
    bad_chunks = cut(faulty(data, args.ber, args.drops), args.read_bytes)
    print(f"\n{n} packets of {PACKET_LEN} bytes in {len(chunks)} reads of {args.read_bytes} bytes\n")

    base = best_cpu(lambda: (struct_loop(chunks), None)[1], args.repeats)
    unit = best_cpu(lambda: unit_decode(chunks)[2], args.repeats)
    unit_bad = best_cpu(lambda: unit_decode(bad_chunks)[2], args.repeats)
    joined = best_cpu(lambda: unit_decode(chunks, joined=True)[2], args.repeats)
    joined_bad = best_cpu(lambda: unit_decode(bad_chunks, joined=True)[2], args.repeats)
    print(f"{'row':<44}{'packets/s (CPU)':>18}{'µs per read':>14}{'vs baseline':>13}")
    for name, cpu, reads in (
        ("struct loop (baseline)", base, len(chunks)),
        ("OpenShoeUnit", unit, len(chunks)),
        ("OpenShoeUnit, wire faults", unit_bad, len(bad_chunks)),
        ("OpenShoeUnit, reads joined (full-speed replay)", joined, len(chunks)),
        ("the same, wire faults", joined_bad, len(bad_chunks)),
    ):
        print(f"{name:<44}{n / cpu:>18,.0f}{1e6 * cpu / reads:>14.1f}{base / cpu:>12.2f}×")

    ref = struct_loop(chunks)
    got, stats, _ = unit_decode(chunks)
    bad, bad_stats, _ = unit_decode(bad_chunks)
    fields = ("counter", "t_s", "acc", "gyr")
    joins_alike = all(
        np.array_equal(getattr(a, f), getattr(b, f))
        for a, b in ((got, unit_decode(chunks, joined=True)[0]), (bad, unit_decode(bad_chunks, joined=True)[0]))
        for f in fields
    )
    same = (
        np.array_equal(got.counter, np.arange(1, n + 1))
        and np.array_equal(got.counter % (1 << 16), ref.counter)
        and np.array_equal(got.acc, ref.acc)
        and np.array_equal(got.gyr, ref.gyr)
        and np.array_equal(got.acc, acc.astype(np.float32).astype(np.float64))
        and np.array_equal(got.gyr, gyr.astype(np.float32).astype(np.float64))
        and np.array_equal(got.t_s, ref.t_s)
    )
    print(f"\nclean stream: {len(got.counter)} of {n} delivered, equal to the struct loop's: {same}; {stats}")
    print(f"faulty stream: {bad_stats}")
    print(f"reads joined: the same samples as read by read, clean and faulty: {joins_alike}")
    return 0 if same and joins_alike else 1


if __name__ == "__main__":
    sys.exit(main())
