"""Wire faults injected by the emulator: every packet the unit sent is received, counted lost or counted repeated.

The host side is the real serial code (pyserial on a pty served by the emulated firmware); the
fault injector logs what it did by package number, and the capture tap must hold every byte that
crossed the wire.
"""

from __future__ import annotations

import asyncio
import contextlib
import math

import numpy as np
import pytest
from footnav.device.emulator.serving.faults import FaultInjector, WireFaults, split_frames
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.protocol.framer import DataPacket, Framer
from footnav.device.protocol.imu import encode_packets
from footnav.device.unit import LinkStats, OpenShoeUnit
from footnav.pipeline.samples import ImuBatch


def _signals(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1000.0
    return t, rng.standard_normal((n, 3)) + np.array([0.0, 0.0, 9.81]), rng.standard_normal((n, 3))


def _packets(n: int) -> bytes:
    _, acc, gyr = _signals(n)
    return encode_packets(np.arange(1, n + 1), np.arange(n) * 64_000, acc, gyr)


# --- the injector alone ---------------------------------------------------------------------------


def test_split_frames_cuts_packets_and_acks_and_rejects_torn_chunks() -> None:
    data = _packets(3) + bytes((0xA0, 0x40, 0x00, 0xE0))
    frames = split_frames(data)
    assert [len(f) for f in frames] == [34, 34, 34, 4]
    with pytest.raises(ValueError, match="runs past the end"):
        split_frames(data[:50])
    with pytest.raises(ValueError, match="does not start a frame"):
        split_frames(b"\x00" + data)


def test_rates_must_be_probabilities() -> None:
    with pytest.raises(ValueError, match="drop_rate"):
        WireFaults(drop_rate=1.0)


def test_injector_is_seeded_and_its_log_matches_what_it_wrote() -> None:
    n = 20_000
    faults = WireFaults(bit_error_rate=2e-5, drop_rate=0.01, duplicate_rate=0.01, reorder_rate=0.01)
    a, b = FaultInjector(faults, seed=4), FaultInjector(faults, seed=4)
    chunks = [_packets(n)[k : k + 34 * 100] for k in range(0, 34 * n, 34 * 100)]
    out_a = [a.apply(c) for c in chunks]
    assert out_a == [b.apply(c) for c in chunks]
    held = a.flush()
    wire = b"".join(data for data, _ in out_a) + held
    log = a.log
    assert log.packets_in == n
    # each rate within 5 sigma of its expectation
    for count, p in ((len(log.dropped), 0.01), (len(log.duplicated), 0.0099), (len(log.reordered), 0.0098)):
        assert abs(count - p * n) < 5 * math.sqrt(p * n)
    expected_flips = 2e-5 * 8 * 34 * n * (1 - 0.01 + 0.0099)
    assert abs(log.bits_flipped - expected_flips) < 5 * math.sqrt(expected_flips)
    # the wire carries what the log says: every data packet but the dropped, the repeats twice
    sent = sum(k for _, k in out_a) + (1 if held else 0)
    assert sent == n - len(log.dropped) + len(log.duplicated)
    assert len(wire) == 34 * sent
    valid = [f for f in Framer().feed(wire) if isinstance(f, DataPacket)]
    numbers = [f.number for f in valid]
    lost_or_hit = set(log.dropped) | set(log.corrupted)
    assert set(range(1, n + 1)) - lost_or_hit <= set(numbers) <= set(range(1, n + 1)) - set(log.dropped)
    assert sum(np.diff(numbers) < 0) >= len(log.reordered) - len(log.corrupted)


# --- on the wire, through the real serial code ----------------------------------------------------


async def _receive(server: PtyShoeServer, n: int) -> tuple[ImuBatch, LinkStats, bytes]:
    """Everything the unit delivers until the emulator has sent its last packet and the line is quiet."""
    rx = bytearray()
    batches: list[ImuBatch] = []
    async with await OpenShoeUnit.open_serial(
        server.port, capture=lambda d, _ns, data: rx.extend(data) if d == "rx" else None
    ) as unit:
        await unit.start_imu_stream(rate_divider_log2=0)
        async with contextlib.aclosing(unit.imu_batches()) as stream:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(60):
                    async for batch in stream:
                        batches.append(batch)
                        if server.finished.is_set() and server.bytes_written == len(rx):
                            break
        stats = unit.stats
    return ImuBatch.concat(batches), stats, bytes(rx)


SCENARIOS = {
    "bit errors 1e-4": WireFaults(bit_error_rate=1e-4),
    "1 % dropped": WireFaults(drop_rate=0.01),
    "1 % duplicated": WireFaults(duplicate_rate=0.01),
    "1 % reordered": WireFaults(reorder_rate=0.01),
    "all at once": WireFaults(bit_error_rate=5e-5, drop_rate=0.005, duplicate_rate=0.005, reorder_rate=0.005),
}


@pytest.mark.parametrize("name", SCENARIOS)
async def test_every_packet_is_received_or_counted(name: str) -> None:
    n = 10_000
    t, acc, gyr = _signals(n, seed=1)
    with PtyShoeServer(t, acc, gyr, speed=math.inf, faults=SCENARIOS[name], split_writes_max=300, seed=7) as server:
        batch, stats, rx = await _receive(server, n)
        log = server.fault_log
        sent = server.sent_bytes
    assert rx == sent  # the capture holds every byte that crossed the wire, in order

    # what a perfect receiver gets from those bytes: the valid copies, each number once
    valid = {f.number for f in Framer(accepted_lengths={28}).feed(sent) if isinstance(f, DataPacket)}
    received = batch.counter.tolist()
    assert len(received) == len(set(received)), "a repeated packet reached the estimators"
    assert set(received) == valid
    assert set(range(1, n + 1)) - set(log.dropped) - set(log.corrupted) <= valid
    assert not valid & set(log.dropped)
    # no corrupted packet passed as valid: the samples are the ones sent
    index = batch.counter - 1
    np.testing.assert_array_equal(batch.acc_b_mps2, acc[index].astype(np.float32))
    np.testing.assert_array_equal(batch.gyr_b_radps, gyr[index].astype(np.float32))
    # the unit's counts account for every number up to the last one it received
    assert stats.lost_packets == max(received) - len(valid)
    copies = sum(isinstance(f, DataPacket) for f in Framer(accepted_lengths={28}).feed(sent))
    assert stats.duplicates == copies - len(valid)
    if log.corrupted:
        assert stats.checksum_errors + stats.bad_lengths > 0
    if log.reordered:
        assert stats.out_of_order > 0
    # within each read the unit restores the order; only a late packet whose successors went out
    # in an earlier read steps back
    assert np.count_nonzero(np.diff(batch.counter) < 0) <= stats.out_of_order


@pytest.mark.slow
async def test_stalls_at_real_time_lose_nothing() -> None:
    n = 3000
    t, acc, gyr = _signals(n, seed=2)
    with PtyShoeServer(t, acc, gyr, speed=1.0, stall_every_s=1.0, stall_s=0.4) as server:
        batch, stats, rx = await _receive(server, n)
        stalls = server.stalls
        sent = server.sent_bytes
    assert stalls >= 2
    assert rx == sent
    np.testing.assert_array_equal(batch.counter, np.arange(1, n + 1))
    assert (stats.lost_packets, stats.duplicates, stats.checksum_errors) == (0, 0, 0)
    # the backlog of each stall arrived in bursts: reads of 400 ms of packets at once
    assert np.max(np.diff(batch.host_ns)) > 0.3e9
