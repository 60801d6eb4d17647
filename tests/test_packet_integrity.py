"""Corruptions the 16-bit checksum misses: a packet number one packet cannot derail, values no unit sends.

Sequence tracking (``footnav.device.protocol.sequence``) is tested alone, with properties over long
streams, then through the unit driver and the real serial path in every output mode; the
plausibility checks (``footnav.device.protocol.integrity``) against every real recording; and the
whole chain, ``footnav live`` on a faulty emulated wire, by accounting for every packet sent.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
from pathlib import Path

import numpy as np
import pytest
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.device.emulator.scripts import InsTruth, steps_from_truth, yaw_from_quat_wxyz
from footnav.device.emulator.serving.faults import WireFaults
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.files.recordings import load_recording
from footnav.device.modes import InsMode, Mode, NormalImuMode, RawImuMode, StepwiseMode
from footnav.device.protocol import integrity
from footnav.device.protocol.commands import CommandSet
from footnav.device.protocol.ins_states import InsStateBatch
from footnav.device.protocol.raw_imu import RawImuBatch
from footnav.device.protocol.sequence import NEAR_BEHIND, CounterTracker
from footnav.device.protocol.stepwise import StepBatch, StepwiseTracker, encode_payloads
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.samples import ImuBatch
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from benchmarks.integrity import MemoryLink, account, deliver, faulty_chunks, live_run, summary_counts, walk

FUZZ = settings(
    max_examples=int(os.environ.get("FOOTNAV_FUZZ_EXAMPLES", "40")),
    deadline=None,
    derandomize="FOOTNAV_FUZZ_EXAMPLES" not in os.environ,
)
PERIOD = 64_000  # 1 kHz in 64 MHz ticks
N_LONG = 1500


def feed(
    tracker: CounterTracker, numbers: list[int], ticks: list[int] | None, sizes: list[int]
) -> list[tuple[int, int]]:
    """Feed ``numbers`` (and ``ticks``) in reads of the given sizes (cycled); returns the delivered
    (stream position, unwrapped counter) pairs in delivery order."""
    out: list[tuple[int, int]] = []
    held: list[int] = []  # stream positions of the packets the tracker holds
    i = k = 0
    while i < len(numbers):
        size = sizes[k % len(sizes)]
        k += 1
        part = slice(i, i + size)
        tracked = tracker.track(np.asarray(numbers[part]) % 65536, None if ticks is None else np.asarray(ticks[part]))
        positions = held + list(range(i, min(i + size, len(numbers))))
        out += [(positions[j], int(c)) for j, c in zip(tracked.positions, tracked.counter, strict=True)]
        held = [positions[j] for j in tracked.held]
        i += size
    return out


def stream(n: int, first: int = 1) -> tuple[list[int], list[int]]:
    numbers = list(range(first, first + n))
    return numbers, [(7_777 + k * PERIOD) % (1 << 32) for k in range(n)]


# --- the tracker alone ------------------------------------------------------------------------------


@pytest.mark.parametrize("with_ticks", [False, True])
def test_one_number_16384_ahead_costs_that_packet_only(with_ticks: bool) -> None:
    numbers, ticks = stream(20_000)
    numbers[999] = 1000 + 16_384
    tracker = CounterTracker()
    sizes = [int(s) for s in np.random.default_rng(0).integers(5, 16, 3000)]  # reads of about ten packets
    got = feed(tracker, numbers, ticks if with_ticks else None, sizes)
    assert len(got) == 19_999
    assert [c for _, c in got] == [k for k in range(1, 20_001) if k != 1000]
    assert (tracker.corrupt_numbers, tracker.duplicates, tracker.lost, tracker.held) == (1, 0, 0, 0)


@FUZZ
@given(
    at=st.integers(50, N_LONG - 10),
    offset=st.integers(-32_768, 32_767),
    sizes=st.lists(st.integers(1, 40), min_size=1, max_size=8),
    with_ticks=st.booleans(),
    first=st.integers(0, 65_535),
)
def test_any_single_corrupt_number_loses_only_that_packet(
    at: int, offset: int, sizes: list[int], with_ticks: bool, first: int
) -> None:
    # without time stamps a number near its run cannot be told from a gap or a repeat: far ones only
    assume(offset != 0 and (with_ticks or not -NEAR_BEHIND - 1 <= offset <= 65))
    numbers, ticks = stream(N_LONG, first)
    numbers[at] += offset
    tracker = CounterTracker()
    got = feed(tracker, numbers, ticks if with_ticks else None, sizes)
    assert [p for p, _ in got] == [p for p in range(N_LONG) if p != at]
    assert [c for _, c in got] == [first + p for p in range(N_LONG) if p != at]
    assert (tracker.corrupt_numbers, tracker.duplicates, tracker.lost) == (1, 0, 0)


@FUZZ
@given(
    at=st.integers(50, N_LONG - 30),
    offsets=st.lists(st.integers(200, 65_336), min_size=2, max_size=12),
    sizes=st.lists(st.integers(1, 40), min_size=1, max_size=8),
    with_ticks=st.booleans(),
)
def test_a_burst_of_corrupt_numbers_loses_only_the_burst(
    at: int, offsets: list[int], sizes: list[int], with_ticks: bool
) -> None:
    numbers, ticks = stream(N_LONG)
    burst = [(numbers[at + j] + off) % 65536 for j, off in enumerate(offsets)]
    # numbers hit independently: no two of them form a run of their own
    assume(all(abs((a - b + 32_768) % 65_536 - 32_768) > 2 * NEAR_BEHIND for a in burst for b in burst if a is not b))
    numbers[at : at + len(burst)] = burst
    tracker = CounterTracker()
    got = feed(tracker, numbers, ticks if with_ticks else None, sizes)
    kept = [p for p in range(N_LONG) if not at <= p < at + len(burst)]
    assert [p for p, _ in got] == kept
    assert (tracker.corrupt_numbers, tracker.duplicates, tracker.lost) == (len(burst), 0, 0)


@FUZZ
@given(
    drops=st.sets(st.integers(1, N_LONG - 2), max_size=60),
    swaps=st.sets(st.integers(1, N_LONG - 3), max_size=30),
    repeats=st.sets(st.integers(1, N_LONG - 2), max_size=30),
    sizes=st.lists(st.integers(2, 40), min_size=1, max_size=8),
    with_ticks=st.booleans(),
)
def test_gaps_repeats_and_reordering_are_handled_as_before(
    drops: set[int], swaps: set[int], repeats: set[int], sizes: list[int], with_ticks: bool
) -> None:
    numbers, ticks = stream(N_LONG)
    order = [p for p in range(N_LONG) if p not in drops]
    for p in sorted(repeats - drops):
        order.insert(order.index(p) + 1, p)
    for s in sorted(swaps):  # a packet sent after its successor
        if s + 1 < len(order) and order[s] != order[s + 1]:
            order[s], order[s + 1] = order[s + 1], order[s]
    tracker = CounterTracker()
    got = feed(tracker, [numbers[p] for p in order], [ticks[p] for p in order] if with_ticks else None, sizes)
    delivered = sorted(c for _, c in got)
    assert delivered == sorted(set(numbers) - {numbers[p] for p in drops})
    assert tracker.corrupt_numbers == 0 and tracker.held == 0
    assert tracker.lost == len(drops)
    assert tracker.duplicates == len(repeats - drops)


@pytest.mark.parametrize("with_ticks", [False, True])
@pytest.mark.parametrize("jump", [500, 16_384, -5_000])
def test_a_real_jump_is_believed_once_the_packets_after_it_continue(with_ticks: bool, jump: int) -> None:
    """A replug after a unit went on numbering (forward), or a unit that restarted (backward)."""
    numbers, ticks = stream(3000, first=10_000)
    numbers[1000:] = [n + jump for n in numbers[1000:]]
    if jump > 0:  # the unit went on counting time too
        ticks[1000:] = [(t + jump * PERIOD) % (1 << 32) for t in ticks[1000:]]
    tracker = CounterTracker()
    got = feed(tracker, numbers, ticks if with_ticks else None, [10])
    assert len(got) == 3000 and tracker.corrupt_numbers == 0 and tracker.duplicates == 0
    assert tracker.lost == max(jump, 0)  # the numbers skipped
    assert np.all(np.diff([c for _, c in got]) > 0)


def test_stepwise_tracker_rejects_a_corrupt_number_and_applies_the_resend() -> None:
    n = 12
    rows = encode_payloads(np.tile([0.5, 0.0, 0.0], (n, 1)), np.zeros(n), np.zeros((n, 4, 4)), np.arange(n))
    tracker = StepwiseTracker()
    # lossless: packet 5 arrives numbered 5 + 4096, is not ACKed by its number, and comes again
    order = [1, 2, 3, 4, 5 + 4096, 5, 6, 7, 8, 9, 10, 11, 12]
    applied: list[int] = []
    for num in order:
        batch = tracker.update([num], rows[(num if num <= n else 5) - 1].tobytes())
        if batch is not None:
            applied += batch.counter.tolist()
    assert applied == list(range(1, n + 1))
    assert (tracker.corrupt_numbers, tracker.repeats_ignored) == (1, 0)


# --- through the unit driver and the serial path ------------------------------------------------------


def test_unit_driver_delivers_19999_of_20000_with_one_corrupt_number() -> None:
    n = 20_000
    _, acc, gyr = walk(20.0)
    chunks, log, _ = faulty_chunks(n, acc, gyr, WireFaults(renumber=((1000, 1000 + 16_384),)))
    assert log.renumbered == [1000] and max(len(c) for c in chunks) <= 15 * 34  # reads of about ten packets
    d = asyncio.run(deliver(MemoryLink(chunks), command_set=CommandSet.V2015))
    np.testing.assert_array_equal(d.counter, [k for k in range(1, n + 1) if k != 1000])
    s = d.stats
    assert (s.corrupt_numbers, s.duplicates, s.lost_packets, s.implausible_rejected) == (1, 0, 0, 0)


async def _serve(mode: Mode, server: PtyShoeServer, kind: type, n: int) -> tuple[list[object], OpenShoeUnit]:
    batches: list[object] = []
    async with await OpenShoeUnit.open_serial(server.port) as unit:
        await unit.start(mode)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(60), contextlib.aclosing(unit.batches()) as stream:
                async for batch in stream:
                    if isinstance(batch, kind):
                        batches.append(batch)
                    if sum(len(b) for b in batches) >= n - 1 and server.finished.is_set():  # type: ignore[arg-type]
                        break
        return batches, unit


@pytest.fixture(scope="module")
def gait() -> GaitTruth:
    return simulate_walk("rectangle", 22.0, seed=3)


MODES = {
    "normal": (NormalImuMode(0), ImuBatch, 1),
    "raw": (RawImuMode(imu_mask=0b11, rate_divider_log2=0), RawImuBatch, 1),
    "ins": (InsMode(state_ids=(0x01, 0x20, 0x21, 0x22), rate_divider_log2=2), InsStateBatch, 4),
    "steps": (StepwiseMode(), StepBatch, 0),
}


@pytest.mark.parametrize("name", MODES)
async def test_every_mode_loses_only_the_packet_with_the_corrupt_number(name: str, gait: GaitTruth) -> None:
    mode, kind, every = MODES[name]
    w = gait
    n_samples = 20_000
    steps = steps_from_truth(w.t_s, w.pos_n_m, yaw_from_quat_wxyz(w.quat_nb_wxyz), w.stance)
    n = len(steps) if every == 0 else n_samples // every
    bad = n // 2 if every == 0 else 1000
    cov = np.tile(np.eye(9) * 1e-4, (len(w), 1, 1))
    server = PtyShoeServer(
        w.t_s[:n_samples], w.acc_b_mps2[:n_samples], w.gyr_b_radps[:n_samples], speed=math.inf,
        imu_acc_b_mps2=np.repeat(w.acc_b_mps2[:n_samples, None], 2, axis=1),
        imu_gyr_b_radps=np.repeat(w.gyr_b_radps[:n_samples, None], 2, axis=1),
        ins=InsTruth(w.pos_n_m, w.vel_n_mps, w.quat_nb_wxyz, cov), steps=steps, resend_interval_s=0.005,
        faults=WireFaults(renumber=((bad, bad + 16_384),)),
    )  # fmt: skip
    with server:
        batches, unit = await _serve(mode, server, kind, n)
        log = server.fault_log
    assert log.renumbered == [bad]
    counters = np.concatenate([b.counter for b in batches])  # type: ignore[attr-defined]
    expected = np.arange(1, n + 1)
    if every == 0:  # lossless: the unit resends the packet it was not ACKed for, so nothing is lost
        np.testing.assert_array_equal(counters, expected)
    else:
        np.testing.assert_array_equal(counters, expected[expected != bad])
    s = unit.stats
    assert (s.corrupt_numbers, s.lost_packets, s.implausible_rejected) == (1, 0, 0)
    if every:  # (lossless resends are repeats by design)
        assert s.duplicates == 0


async def test_bit_errors_and_garbage_together_keep_the_emulator_serving() -> None:
    n = 6000
    _, acc, gyr = walk(6.0)
    t = np.arange(n) / 1000.0
    faults = WireFaults(bit_error_rate=1e-2, drop_rate=0.05, duplicate_rate=0.02, reorder_rate=0.02)
    with PtyShoeServer(t, acc, gyr, speed=math.inf, faults=faults, garbage_every=3, seed=11) as server:
        _, unit = await _serve(NormalImuMode(0), server, ImuBatch, 1)
        finished, error = server.finished.wait(30), server.error
    assert error is None and finished  # before: "does not start a frame", a dead unit to the host
    assert unit.stats.checksum_errors > 0 and unit.stats.bytes_skipped > 0


# --- what the checksum misses -------------------------------------------------------------------------


def test_value_checks_keep_every_sample_of_real_recordings_and_the_emulated_stairs(shared_data: Path) -> None:
    files = sorted(p for p in shared_data.rglob("*") if p.suffix in (".mat", ".csv", ".txt"))
    assert len(files) >= 11  # nine PyShoe trials (two with running), x-io, OpenShoe
    for path in files:
        rec = load_recording(path)
        ok = integrity.ImuGuard().check(np.arange(len(rec)), rec.acc_b_mps2, rec.gyr_b_radps)
        assert ok.all(), f"{path.name}: {np.count_nonzero(~ok)} samples rejected"
    for speed in (1.2, 1.4, 1.8):
        stairs = simulate_walk("stairs", 60.0, speed_mps=speed, seed=4)
        assert integrity.ImuGuard().check(np.arange(len(stairs.t_s)), stairs.acc_b_mps2, stairs.gyr_b_radps).all()
        quat = stairs.quat_nb_wxyz
        assert integrity.ins_plausible(stairs.pos_n_m, stairs.vel_n_mps, quat).all()
        steps = steps_from_truth(stairs.t_s, stairs.pos_n_m, yaw_from_quat_wxyz(quat), stairs.stance)
        assert integrity.step_plausible(steps.dx_m, steps.dheading_rad, steps.cov_4x4).all()


def test_value_checks_reject_what_no_unit_sends() -> None:
    n = 200
    _, acc, gyr = walk(1.0)
    acc, gyr = acc[:n].copy(), gyr[:n].copy()
    acc[50, 2] = 1.9e20  # an exponent bit
    gyr[80, 0] = 72.8  # beyond ±2000 °/s
    acc[120, 0] += 350.0  # within range on its own but a step no foot makes
    gyr[150, 1] = np.nan
    guard = integrity.ImuGuard()
    ok = guard.check(np.arange(n), acc, gyr)
    assert np.flatnonzero(~ok).tolist() == [50, 80, 120, 150] and guard.rejected == 4
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    quat[1] = [0.5, 0.5, 0.0, 0.0]
    assert integrity.ins_plausible(np.zeros((3, 3)), np.array([[0, 0, 0], [0, 0, 0], [0, 80.0, 0]]), quat).tolist() == [
        True,
        False,
        False,
    ]


def test_the_checks_reject_what_they_can_at_a_bit_error_rate_of_1e_3() -> None:
    n = 20_000
    _, acc, gyr = walk(20.0)
    faults = WireFaults(bit_error_rate=1e-3, drop_rate=0.05, duplicate_rate=0.02, reorder_rate=0.02)
    chunks, log, ticks = faulty_chunks(n, acc, gyr, faults, seed=8)
    d = asyncio.run(deliver(MemoryLink(chunks), command_set=CommandSet.V2015))
    r = account(d, log, acc, gyr, ticks)
    assert r["delivered_twice"] == r["foreign"] == r["missing_unexplained"] == 0
    assert r["accounted"], r
    # what still passes (flips that cancel in the checksum and leave plausible values) was corrupted
    # on the wire, got past the checksum, and is a fraction of what passed it
    assert r["wrong_not_corrupted"] == 0
    assert set(r["wrong_counters"]) <= set(log.undetected)
    assert r["delivered_wrong"] < max(3, 0.7 * r["pass_checksum"]), r
    assert r["corrupt_numbers"] + r["implausible"] > 0


# --- end to end -------------------------------------------------------------------------------------


@pytest.mark.slow
def test_live_accounts_for_every_packet_on_a_faulty_wire(tmp_path: Path) -> None:
    """``footnav live`` at a bit error rate of 1e-3 with drops, repeats, reordering and garbage (the 45 s
    run is ``python -m benchmarks.integrity``)."""
    r = live_run(12.0, tmp_path, speed=2.0)
    counts = summary_counts(r.pop("stdout"))
    err = r.pop("stderr")
    assert "Traceback" not in err
    assert r["sent"] == 12_000 and r["dropped"] > 300 and r["corrupted"] > 1000
    assert r["delivered_twice"] == r["foreign"] == r["missing_unexplained"] == 0
    assert r["accounted"], r
    # the session's own line says what the replay of its capture finds
    assert counts == {
        "samples": r["delivered"],
        "lost": r["lost"],
        "corrupt_numbers": r["corrupt_numbers"],
        "implausible": r["implausible"],
    }
    assert r["delivered"] + r["lost"] + r["corrupt_numbers"] + r["implausible"] >= r["sent"] - 1
    assert r["wrong_not_corrupted"] == 0 and r["delivered_wrong"] <= r["pass_checksum"]
    assert "stopped streaming" not in err  # no good packet was taken for a repeat
