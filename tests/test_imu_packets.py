"""Normal-IMU packet encode/decode, tick unwrapping and package-number accounting."""

from __future__ import annotations

import numpy as np
import pytest
from footnav.device.protocol.commands import data_packet
from footnav.device.protocol.framer import DataPacket, Framer
from footnav.device.protocol.imu import (
    PACKET_LEN,
    TICK_HZ,
    CounterTracker,
    TickUnwrapper,
    decode_payloads,
    encode_packets,
    seconds_to_ticks,
)


def _samples(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(0, 9.81, (n, 3)), rng.normal(0, 3.0, (n, 3))


def test_encode_matches_reference_packet_layout() -> None:
    acc = np.array([[1.0, -2.0, 9.81]])
    gyr = np.array([[0.5, 0.0, -0.25]])
    raw = encode_packets(np.array([0x0102]), np.array([0xDEADBEEF]), acc, gyr)
    payload = bytes.fromhex("DEADBEEF") + np.array([1.0, -2.0, 9.81, 0.5, 0.0, -0.25], ">f4").tobytes()
    assert raw == data_packet(0x0102, payload)  # the scalar codec agrees byte for byte
    assert len(raw) == PACKET_LEN


def test_round_trip_through_framer() -> None:
    n = 5000
    acc, gyr = _samples(n)
    ticks = seconds_to_ticks(np.arange(n) / 1000.0, tick0=2**32 - 64_000 * 100)
    numbers = np.arange(65_000, 65_000 + n)  # wraps through 65535 -> 0
    raw = encode_packets(numbers, ticks, acc, gyr)
    frames = Framer(accepted_lengths={28}).feed(raw)
    assert all(isinstance(f, DataPacket) for f in frames)
    assert [f.number for f in frames] == list(numbers % 65536)
    arrays = decode_payloads(b"".join(f.payload for f in frames if isinstance(f, DataPacket)))
    np.testing.assert_array_equal(arrays.ticks, ticks)
    np.testing.assert_array_equal(arrays.acc_b_mps2, acc.astype(np.float32))
    np.testing.assert_array_equal(arrays.gyr_b_radps, gyr.astype(np.float32))
    assert arrays.acc_b_mps2.dtype == np.float64


def test_decode_rejects_partial_payloads() -> None:
    with pytest.raises(ValueError, match="28 bytes each"):
        decode_payloads(bytes(29))


def test_tick_unwrap_across_wrap_in_pieces() -> None:
    t = np.arange(0, 200.0, 0.001)  # ~3 wraps of the 67.1 s counter
    tick0 = 2**32 - 64_000_000  # wraps 1 s in
    ticks = seconds_to_ticks(t, tick0)
    unwrap = TickUnwrapper()
    parts = [unwrap.update(chunk) for chunk in np.array_split(ticks, 37)]
    t_s = np.concatenate(parts)
    np.testing.assert_allclose(t_s - t_s[0], t, atol=1 / TICK_HZ)
    assert t_s[0] == pytest.approx(tick0 / TICK_HZ)
    assert np.all(np.diff(t_s) > 0)
    assert unwrap.wraps == 3
    assert unwrap.update(np.empty(0, np.uint32)).shape == (0,)


def test_tick_unwrap_wrap_exactly_between_batches() -> None:
    unwrap = TickUnwrapper()
    a = unwrap.update(np.array([2**32 - 64_000], dtype=np.uint32))
    b = unwrap.update(np.array([0, 64_000], dtype=np.uint32))
    np.testing.assert_allclose(np.diff(np.concatenate([a, b])), [0.001, 0.001])


def test_counter_gaps_duplicates_and_wrap() -> None:
    tracker = CounterTracker()
    c1, d1 = tracker.update(np.array([65533, 65534, 65535]))
    c2, d2 = tracker.update(np.array([0, 0, 3, 4, 2]))  # wrap, duplicate, 1 and 2 missing, 2 late
    np.testing.assert_array_equal(c1, [65533, 65534, 65535])
    np.testing.assert_array_equal(c2, [65536, 65536, 65539, 65540, 65538])
    np.testing.assert_array_equal(np.concatenate([d1, d2]), [0, 0, 0, 0, 1, 0, 0, 0])
    assert (tracker.lost, tracker.duplicates, tracker.out_of_order) == (1, 1, 1)
    tracker.update(np.array([1, 5, 5]))  # the other late one closes the gap; a repeat
    assert (tracker.lost, tracker.duplicates, tracker.out_of_order) == (0, 2, 2)


def test_counter_non_adjacent_repeat_is_a_duplicate_not_a_gap() -> None:
    tracker = CounterTracker()
    _, dup = tracker.update(np.array([5, 6, 7, 5, 8]))
    np.testing.assert_array_equal(dup, [0, 0, 0, 1, 0])
    assert (tracker.lost, tracker.duplicates, tracker.out_of_order) == (0, 1, 0)


def test_counter_gaps_older_than_the_window_stay_lost() -> None:
    tracker = CounterTracker(window=10)
    tracker.update(np.array([0, 3]))
    tracker.update(np.arange(4, 30))
    tracker.update(np.array([1]))  # too late: counted as a repeat of a number given up on
    assert tracker.lost == 2 and tracker.out_of_order == 0
