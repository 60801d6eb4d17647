"""The vectorised decoding of a run of packets gives what the packet-by-packet path gives.

A read that is one run of valid normal-IMU packets continuing the package numbers takes a short path
in the unit driver: the framer's matrix product (checksum, header, number, time stamp), the counter
tracker's run test, the plausibility guard's block test, the payloads widened at once, the shared
clock. Each piece is checked here against the plain rule it implements (written out per packet in
the test), and the whole driver against its general path on the same bytes.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from pathlib import Path

import numpy as np
import pytest
from footnav.device.files.capture import CaptureWriter, UnitHeader
from footnav.device.files.capture_records import chunk_contents
from footnav.device.modes import NormalImuMode
from footnav.device.protocol.commands import CommandSet, data_packet
from footnav.device.protocol.framer import DataPacket, Framer, PacketRun
from footnav.device.protocol.imu import SharedTickClock, decode_imu_rows, decode_payloads, encode_packets
from footnav.device.protocol.integrity import ImuGuard
from footnav.device.protocol.sequence import NO_TICK, CounterTracker
from footnav.device.unit import Batch, OpenShoeUnit
from footnav.pipeline.samples import ImuBatch
from mcap.records import Chunk
from mcap.stream_reader import StreamReader, breakup_chunk

from benchmarks.decode import ChunkLink

W16, W32 = 1 << 16, 1 << 32


# --- framer -------------------------------------------------------------------------------------------


def _stream(rng: np.random.Generator, length: int, n: int, first: int) -> tuple[bytes, list[DataPacket]]:
    """n packets of payload ``length`` numbered from ``first`` (wrapping), random payloads; every fifth
    payload all 0xFF (the largest byte sum: a checksum carry beyond N = 252)."""
    packets = []
    for k in range(n):
        payload = b"\xff" * length if k % 5 == 0 else rng.integers(0, 256, length, dtype=np.uint8).tobytes()
        packets.append(DataPacket((first + k) % W16, payload))
    return b"".join(data_packet(p.number, p.payload) for p in packets), packets


@pytest.mark.parametrize("length", [0, 1, 3, 4, 28, 100, 252, 253, 255])
def test_runs_give_the_packets_of_the_byte_by_byte_path(length: int) -> None:
    rng = np.random.default_rng(length)
    data, sent = _stream(rng, length, 40, W16 - 20)  # the numbers wrap inside the run
    bad = bytearray(data)
    stride = length + 6
    bad[25 * stride + 2 + (length // 2)] ^= 0x10  # one bit of packet 25 (its number or payload)
    for stream, expect in ((data, sent), (bytes(bad), sent[:25] + sent[26:])):
        framer = Framer()
        frames = framer.feed_runs(stream)
        runs = [f for f in frames if type(f) is PacketRun]
        assert runs and len(runs[0]) >= 8
        got = [p for f in frames for p in (f.packets() if type(f) is PacketRun else [f])]
        assert got == expect
        for run in runs:
            if length >= 4:
                assert run.heads is not None
                assert run.heads.tolist() == [int.from_bytes(row.tobytes()[:4], "big") for row in run.payloads]
            else:
                assert run.heads is None
        # fed a byte at a time no run can form: the packet-by-packet path
        single = Framer()
        assert [f for i in range(len(stream)) for f in single.feed(stream[i : i + 1])] == expect
        assert framer.stats == single.stats


def test_a_run_takes_the_checksum_modulo_2_16_beyond_252_bytes() -> None:
    """Beyond N = 252 the byte sum can exceed 2**16: the checksum is the sum modulo 2**16, one off is wrong."""
    stride = 261
    good = data_packet(0xFFFF, b"\xff" * 255)
    total = sum(good[: stride - 2])
    assert total > W16 and int.from_bytes(good[-2:], "big") == total % W16
    framer = Framer()
    runs = framer.feed_runs(good * 12)
    assert len(runs) == 1 and type(runs[0]) is PacketRun and len(runs[0]) == 12
    for wrong in (total % W16 + 1, total % W16 - 1):
        bad = bytearray(good * 12)
        bad[7 * stride - 2 : 7 * stride] = wrong.to_bytes(2, "big")  # the checksum of packet 6
        framer = Framer()
        got = [p for f in framer.feed_runs(bytes(bad)) for p in (f.packets() if type(f) is PacketRun else [f])]
        assert len(got) == 11
        assert framer.stats.checksum_errors == 1


# --- counter tracker --------------------------------------------------------------------------------


def _continues_rule(tracker: CounterTracker, numbers: list[int], ticks: list[int] | None) -> bool:
    """``CounterTracker.continues`` as the module docstring states it, one packet at a time."""
    if tracker._high is None or tracker._pending or not numbers:
        return False
    if numbers[0] != (tracker._high_raw + 1) % W16 or any((b - a) % W16 != 1 for a, b in itertools.pairwise(numbers)):
        return False
    if ticks is None:
        return True
    if NO_TICK in ticks:
        return all(t == NO_TICK for t in ticks)
    period, ref = tracker.period_ticks, tracker._ref
    if period is None or ref is None:
        return False
    tol = period // 4
    lead = tracker._high + 1 - ref[0]
    first = (ticks[0] - ref[1] - lead * period + W32 // 2) % W32 - W32 // 2
    if abs(first) > tol + lead * period // 2000:
        return False
    return all(abs((b - a) % W32 - period) <= tol for a, b in itertools.pairwise(ticks))


def test_continues_follows_its_rule_for_short_and_long_reads() -> None:
    rng = np.random.default_rng(1)
    period = 64_000
    checked = {True: 0, False: 0}
    for trial in range(3000):
        tracker = CounterTracker()
        high = int(rng.integers(0, W16))
        tick0 = int(rng.integers(0, W32))
        # a believed run up to ``high`` whose last tick is ``tick0``
        tracker._high, tracker._high_raw = 1000 + high, high
        tracker.period_ticks, tracker._ref = period, (1000 + high, tick0)
        m = int(rng.choice([1, 2, 5, 12, 13, 30, 64, 65, 300]))
        numbers = [(high + 1 + k) % W16 for k in range(m)]
        ticks = [(tick0 + (k + 1) * period + int(rng.integers(-100, 100))) % W32 for k in range(m)]
        fault = trial % 8
        if fault == 1:
            numbers[int(rng.integers(0, m))] ^= 1 << int(rng.integers(0, 16))
        elif fault == 2:
            ticks[int(rng.integers(0, m))] += int(rng.choice([-1, 1])) * int(
                rng.integers(period // 4 - 200, 2 * period)
            )
        elif fault == 3:
            ticks[int(rng.integers(0, m))] = NO_TICK
        elif fault == 4:
            ticks = [NO_TICK] * m
        elif fault == 5:  # every step right, the whole read half a period late
            ticks = [t + period // 2 for t in ticks]
        elif fault == 6:
            tracker.period_ticks = None
        ticks = [t % W32 if t != NO_TICK else t for t in ticks]
        expect = _continues_rule(tracker, numbers, ticks)
        assert tracker.continues(np.array(numbers), np.array(ticks)) == expect, (trial, m, fault)
        assert tracker.continues(np.array(numbers)) == _continues_rule(tracker, numbers, None)
        checked[expect] += 1
    assert min(checked.values()) > 500  # both answers were tested often


# --- plausibility guard ---------------------------------------------------------------------------


def test_accepts_all_only_when_check_accepts_every_record() -> None:
    rng = np.random.default_rng(2)
    block_guard, record_guard = ImuGuard(), ImuGuard()
    counter = quick = 0
    for trial in range(400):
        m = int(rng.integers(1, 80))
        x = np.concatenate((rng.normal(0, 20, (m, 3)), rng.normal(0, 3, (m, 3))), axis=1)
        x = np.cumsum(x * 0.05, axis=0) + rng.normal(0, 1, 6)
        kind = trial % 6
        i = int(rng.integers(0, m))
        if kind == 1:
            x[i, int(rng.integers(0, 6))] = np.nan
        elif kind == 2:
            x[i, int(rng.integers(0, 3))] = 196.2 * rng.choice([-1.0, 1.0]) * 1.001  # out of range
        elif kind == 3:
            x[i:, int(rng.integers(3, 6))] += 41.0  # a step no foot makes
        elif kind == 4:
            x[i, 0] = 196.13  # in range, just
        counters = np.arange(counter, counter + m, dtype=np.int64)
        counter += m
        ok = record_guard.check(counters, x[:, :3], x[:, 3:])
        if block_guard.accepts_all(counters, x, 3):
            assert ok.all(), trial
            quick += 1
        else:  # the quick test says nothing: the record by record rule decides
            assert np.array_equal(block_guard.check_rows(counters, x, 3), ok)
        assert block_guard.rejected == record_guard.rejected
        assert block_guard._last is not None and record_guard._last is not None
        assert block_guard._last[0] == record_guard._last[0]
        assert np.array_equal(block_guard._last[1], record_guard._last[1])
    assert quick > 100


# --- clock and payloads ------------------------------------------------------------------------------


def test_shared_clock_steps_by_signed_differences_modulo_2_32() -> None:
    rng = np.random.default_rng(3)
    ticks = (W32 - 300_000 + np.cumsum(rng.integers(-2_000, 70_000, 400))) % W32  # wraps, steps back a little
    ticks[200] = (ticks[199] + W32 // 2 - 1) % W32  # the largest forward step
    ticks[201] = (ticks[200] - W32 // 2) % W32  # the largest backward step
    clock = SharedTickClock()
    got = np.concatenate([clock.update(ticks[a:b]) for a, b in ((0, 1), (1, 37), (37, 38), (38, 250), (250, 400))])
    total = [int(ticks[0])]
    for a, b in itertools.pairwise(ticks.tolist()):
        total.append(total[-1] + (b - a + W32 // 2) % W32 - W32 // 2)
    assert np.array_equal(got, np.array(total) / 64e6)


def test_decode_imu_rows_equals_decode_payloads_nan_included() -> None:
    rng = np.random.default_rng(4)
    rows = rng.integers(0, 256, (50, 34), dtype=np.uint8)
    rows[3, 8:12] = (0x7F, 0xA0, 0x00, 0x01)  # a signalling NaN: widened without a warning
    rows[4, 12:16] = (0xFF, 0x80, 0x00, 0x00)  # -inf
    payloads = rows[:, 4:32]
    imu = decode_imu_rows(payloads)
    ref = decode_payloads(payloads.tobytes())
    assert imu.dtype == np.float64 and imu.flags.c_contiguous
    assert np.array_equal(imu[:, :3], ref.acc_b_mps2, equal_nan=True)
    assert np.array_equal(imu[:, 3:], ref.gyr_b_radps, equal_nan=True)
    assert np.isnan(imu[3, 0]) and imu[4, 1] == -np.inf
    with pytest.raises(ValueError, match="28 bytes"):
        decode_imu_rows(rows[:, :27])


# --- the unit driver: short path against general path ------------------------------------------------


async def _deliver(chunks: list[bytes], *, general: bool) -> tuple[list[ImuBatch], dict[str, int | str]]:
    """What the driver delivers, and its counts (``short``: reads the short path took)."""
    unit = OpenShoeUnit(ChunkLink(chunks), command_set=CommandSet.V2015)
    short = 0
    normal_run = unit._normal_run

    def counted(run: PacketRun, host_ns: int) -> list[Batch] | None:
        nonlocal short
        out = None if general else normal_run(run, host_ns)
        short += out is not None
        return out

    unit._normal_run = counted  # type: ignore[method-assign]
    if general:  # and every read packet by packet
        unit._normal_only = lambda frames: False  # type: ignore[method-assign]
        unit._counters._forward = lambda raw, tick: None  # type: ignore[method-assign]
    await unit.start(NormalImuMode(0))
    got: list[ImuBatch] = []
    async with contextlib.aclosing(unit.imu_batches()) as stream:
        async for batch in stream:
            got.append(batch)
    stats = unit.stats
    return got, {"short": short} | {k: getattr(stats, k) for k in stats.__dataclass_fields__}


def _walk_wire(seconds: float) -> bytes:
    """An emulated walk at 1 kHz as normal-IMU packets: a tick wrap, a number wrap, implausible values
    that pass the checksum (beyond the range; a step no foot makes, three samples long)."""
    from footnav.device.emulator.motion.gait import simulate_walk

    w = simulate_walk("rectangle", seconds, seed=1)
    n = len(w.t_s)
    acc, gyr = w.acc_b_mps2.copy(), w.gyr_b_radps.copy()
    acc[3000] = (500.0, 0.0, 0.0)
    gyr[9000:9003, 2] += 60.0
    numbers = np.arange(W16 - 5000, W16 - 5000 + n)
    ticks = (W32 - 8_000 * 64_000 + np.arange(n, dtype=np.int64) * 64_000) % W32
    return encode_packets(numbers, ticks, acc, gyr)


def _same_batches(fast: list[ImuBatch], slow: list[ImuBatch]) -> None:
    assert len(fast) == len(slow) > 100
    for a, b in zip(fast, slow, strict=True):
        for f in ("t_s", "acc_b_mps2", "gyr_b_radps", "counter"):
            x, y = getattr(a, f), getattr(b, f)
            assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), f
            assert x.flags.c_contiguous
        # the read's host time (a clock reading: equal within the batch, not between the runs)
        assert a.host_ns.dtype == b.host_ns.dtype == np.int64 and a.host_ns.shape == b.host_ns.shape
        assert (a.host_ns == a.host_ns[0]).all()


def test_the_driver_delivers_the_same_batches_on_both_paths() -> None:
    """In 1024-byte reads, with 50 packets lost and a read repeated: every batch and count equals the
    packet-by-packet path's, and nearly every read took the short path."""
    wire = _walk_wire(20.0)
    wire = wire[: 34 * 12_000] + wire[34 * 12_050 :]
    chunks = [wire[k : k + 1024] for k in range(0, len(wire), 1024)]
    chunks.insert(300, chunks[299])
    fast, fast_stats = asyncio.run(_deliver(chunks, general=False))
    slow, slow_stats = asyncio.run(_deliver(chunks, general=True))
    assert int(fast_stats.pop("short")) > 0.95 * len(chunks) and slow_stats.pop("short") == 0
    assert fast_stats == slow_stats
    assert int(fast_stats["implausible_rejected"]) >= 4 and fast_stats["lost_packets"] == 50
    _same_batches(fast, slow)


def test_the_driver_delivers_the_same_batches_from_a_faulty_wire() -> None:
    """Bit errors, drops, repeats, packets late and garbage between reads: the reads with a gap or a bad
    packet go through the array form of the general path (counts, order, held suspects) and equal the
    packet-by-packet path's batches and counts."""
    from footnav.device.emulator.serving.faults import FaultInjector, WireFaults

    wire = _walk_wire(30.0)
    faults = WireFaults(bit_error_rate=2e-4, drop_rate=0.02, duplicate_rate=0.01, reorder_rate=0.01)
    injector = FaultInjector(faults, seed=7)
    out = b"".join(injector.apply(wire[k : k + 3400])[0] for k in range(0, len(wire), 3400)) + injector.flush()
    rng = np.random.default_rng(8)
    chunks = []
    for k in range(0, len(out), 1024):
        chunks.append(out[k : k + 1024])
        if k % 97 == 0:
            chunks.append(rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8).tobytes())
    fast, fast_stats = asyncio.run(_deliver(chunks, general=False))
    slow, slow_stats = asyncio.run(_deliver(chunks, general=True))
    fast_stats.pop("short")
    slow_stats.pop("short")
    assert fast_stats == slow_stats
    for key in ("lost_packets", "duplicates", "out_of_order", "checksum_errors", "corrupt_numbers"):
        assert int(fast_stats[key]) > 0, key
    _same_batches(fast, slow)


# --- capture chunks ----------------------------------------------------------------------------------


def test_chunk_contents_equal_the_mcap_readers(tmp_path: Path) -> None:
    path = tmp_path / "c.mcap"
    rng = np.random.default_rng(5)
    with CaptureWriter(path, flush_period_s=3600.0) as cap:
        taps = {foot: cap.add_unit(UnitHeader(foot, "u", "openshoe-2015", "pty", "/dev/null")) for foot in ("l", "r")}
        for k in range(3000):
            taps["l" if k % 2 else "r"](
                "rx", 1_000 * k, rng.integers(0, 256, int(rng.integers(0, 1100))).astype(np.uint8).tobytes()
            )
            if k % 700 == 0:
                taps["l"]("tx", 1_000 * k + 1, b"\x40\x00\x40")
                cap.event("l", "mark", k=k)
    seen = 0
    with open(path, "rb") as f:
        for rec in StreamReader(f, emit_chunks=True).records:
            if isinstance(rec, Chunk):
                assert chunk_contents(rec) == breakup_chunk(rec, validate_crc=True)
                seen += 1
    assert seen >= 3
