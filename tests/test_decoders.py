"""Payload decoders of every output mode: golden packets, round trips, frame conversion, properties."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from footnav.device.protocol import extensions, ins_states, raw_imu, stepwise
from footnav.device.protocol.commands import data_packet
from footnav.device.protocol.framer import DataPacket, Framer
from footnav.device.protocol.imu import frame_payload_rows
from footnav.device.protocol.raw_imu import RawImuLayout
from hypothesis import given, settings
from hypothesis import strategies as st


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# A full SWDR packet: pkt# 0x0102; dx = (1, -0.5, 0.25) m, dθ = 0.125 rad (z down); Pxx = Pyy = 1/16,
# Pzz = 1/64, Pψψ = 1/256; step counter 7 (protocol-openshoe.md 5.1 offsets).
STEP_PACKET = h(
    "aa 01 02 3a 3f 80 00 00 bf 00 00 00 3e 80 00 00 3e 00 00 00 3d 80 00 00 00 00 00 00 00 00 00 00"
    "00 00 00 00 3d 80 00 00 00 00 00 00 00 00 00 00 3c 80 00 00 00 00 00 00 3b 80 00 00 00 07 06 59"
)
# A raw four-IMU packet (mode 0x28, mask 0x0F): ts 0x01020304, each IMU (+1 g, 0, -1 g, +10, 0, -10 °/s).
RAW4_PACKET = h("aa 00 05 34 01 02 03 04" + " 08 00 00 00 f8 00 00 a4 00 00 ff 5c" * 4 + " 0c e9")


def test_golden_stepwise_packet() -> None:
    assert len(STEP_PACKET) == stepwise.PACKET_LEN == 64
    (frame,) = Framer().feed(STEP_PACKET)
    assert isinstance(frame, DataPacket)
    assert frame.number == 0x0102
    arr = stepwise.decode_payloads(frame.payload)
    np.testing.assert_array_equal(arr.dx_m, [[1.0, 0.5, -0.25]])  # y and z flipped: z up
    np.testing.assert_array_equal(arr.dheading_rad, [-0.125])
    np.testing.assert_array_equal(np.diag(arr.cov_4x4[0]), [1 / 16, 1 / 16, 1 / 64, 1 / 256])
    assert arr.step_counter.tolist() == [7]
    encoded = stepwise.encode_payloads(arr.dx_m, arr.dheading_rad, arr.cov_4x4, arr.step_counter)
    assert data_packet(0x0102, encoded.tobytes()) == STEP_PACKET  # both directions


def test_golden_raw_four_imu_packet() -> None:
    assert len(RAW4_PACKET) == 58
    (frame,) = Framer().feed(RAW4_PACKET)
    assert isinstance(frame, DataPacket)
    layout = RawImuLayout.from_command(0x0F, 0x42)
    assert layout.payload_len == 52
    arr = raw_imu.decode_payloads(frame.payload, layout)
    assert arr.ticks.tolist() == [0x01020304]
    np.testing.assert_allclose(arr.acc_b_mps2[0], np.tile([9.80665, 0, -9.80665], (4, 1)))
    np.testing.assert_allclose(arr.gyr_b_radps[0], np.tile(np.radians([10.0, 0, -10.0]), (4, 1)))
    regs = raw_imu.si_to_registers(arr.acc_b_mps2, arr.gyr_b_radps)
    rows = raw_imu.encode_payloads(layout, arr.ticks, regs)
    assert frame_payload_rows(np.array([5]), rows).tobytes() == RAW4_PACKET


@pytest.mark.parametrize("mask", [0b1, 0b11, 0b1010, 0b1111])
@pytest.mark.parametrize(("temperature", "magnetometer"), [(False, False), (True, True)])
def test_raw_round_trip_any_subset(mask: int, temperature: bool, magnetometer: bool) -> None:
    layout = RawImuLayout(raw_imu.mask_to_ids(mask), temperature=temperature, magnetometer=magnetometer)
    k = layout.n_imus
    assert layout.payload_len == 4 + 12 * k + 2 * k * temperature + 6 * k * magnetometer
    rng = np.random.default_rng(mask)
    regs = rng.integers(-32768, 32768, (50, k, 6)).astype(np.int16)
    temp = rng.integers(-32768, 32768, (50, k)).astype(np.int16)
    mag = rng.integers(-32768, 32768, (50, k, 3)).astype(np.int16)
    ticks = rng.integers(0, 2**32, 50)
    rows = raw_imu.encode_payloads(layout, ticks, regs, temp, mag)
    arr = raw_imu.decode_payloads(rows.tobytes(), layout)
    np.testing.assert_array_equal(raw_imu.si_to_registers(arr.acc_b_mps2, arr.gyr_b_radps), regs)
    assert arr.ticks.tolist() == ticks.tolist()
    if temperature:
        np.testing.assert_array_equal(arr.temperature_raw, temp)
        np.testing.assert_array_equal(arr.mag_raw, mag)
    else:
        assert arr.temperature_raw is None and arr.mag_raw is None


def test_raw_scale_saturates_like_the_sensor() -> None:
    regs = raw_imu.si_to_registers(np.array([[200.0, -200.0, 0.0]]), np.array([[100.0, 0.0, 0.0]]))
    assert regs.tolist() == [[32767, -32768, 0, 32767, 0, 0]]
    assert raw_imu.DUAL_IMU_MASK == 0b11 and RawImuLayout((0, 1)).payload_len == 28


def _quat_to_mat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_ins_frame_conversion_is_the_rotation_by_pi_about_x() -> None:
    rng = np.random.default_rng(1)
    q_ned = rng.normal(size=(20, 4))
    q_ned /= np.linalg.norm(q_ned, axis=1, keepdims=True)  # wxyz
    xyzw = q_ned[:, [1, 2, 3, 0]]
    q_up = ins_states.quat_xyzw_ned_to_wxyz_up(xyzw)
    rot = np.diag([1.0, -1.0, -1.0])
    for a, b in zip(q_ned, q_up, strict=True):
        np.testing.assert_allclose(_quat_to_mat(b), rot @ _quat_to_mat(a), atol=1e-12)
    np.testing.assert_allclose(ins_states.quat_wxyz_up_to_xyzw_ned(q_up), xyzw, atol=1e-15)


def test_ins_round_trip_with_covariance() -> None:
    layout = ins_states.InsLayout((0x23, 0x22, 0x01, 0x21, 0x20))  # any order: sorted to wire order
    assert layout.state_ids == (0x01, 0x20, 0x21, 0x22, 0x23)
    assert layout.payload_len == 224
    assert ins_states.InsLayout().payload_len == 44  # ts | pos | vel | quat: a 50-byte packet
    rng = np.random.default_rng(2)
    n = 30
    pos, vel = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    a = rng.normal(size=(n, 9, 9))
    cov = a @ a.transpose(0, 2, 1)
    rows = ins_states.encode_payloads(
        layout, ticks=np.arange(n), pos_n_m=pos, vel_n_mps=vel, quat_nb_wxyz=quat, cov_9x9=cov
    )
    raw = rows.tobytes()
    assert np.frombuffer(raw[4:16], ">f4")[2] == np.float32(-pos[0, 2])  # z down on the wire
    arr = ins_states.decode_payloads(raw, layout)
    np.testing.assert_allclose(arr.pos_n_m, pos, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(arr.vel_n_mps, vel, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(arr.quat_nb_wxyz, quat, atol=1e-7)
    np.testing.assert_allclose(arr.cov_9x9, cov, rtol=1e-6, atol=1e-5)
    packed = ins_states.pack_cov9(np.arange(81.0).reshape(1, 9, 9))
    assert [int(packed[0, i]) for i in (0, 9, 17, 24, 30, 35, 39, 42, 44)] == [
        0,
        10,
        20,
        30,
        40,
        50,
        60,
        70,
        80,
    ]


def test_ins_layout_rejects_unknown_states() -> None:
    with pytest.raises(ValueError, match="INS payloads hold"):
        ins_states.InsLayout((0x20, 0x30))


def test_stepwise_tracker_rotates_dedupes_and_propagates() -> None:
    # Four 1 m steps turning left 90° after each: a closed square.
    n = 4
    dx = np.tile([1.0, 0.0, 0.0], (n, 1))
    dpsi = np.full(n, math.pi / 2)
    q = np.tile(np.diag([1e-4, 1e-4, 1e-6, 1e-4]), (n, 1, 1))
    rows = stepwise.encode_payloads(dx, dpsi, q, np.arange(1, n + 1))
    tracker = stepwise.StepwiseTracker()
    b1 = tracker.update([10, 10, 11], rows[[0, 0, 1]].tobytes())  # a resend of 10 in between
    b2 = tracker.update([11, 12, 13], rows[[1, 2, 3]].tobytes())
    assert b1 is not None and b2 is not None
    np.testing.assert_array_equal(np.concatenate([b1.counter, b2.counter]), [10, 11, 12, 13])
    pos = np.concatenate([b1.pos_n_m, b2.pos_n_m])
    np.testing.assert_allclose(pos, [[1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 0]], atol=1e-6)
    assert tracker.repeats_ignored == 2 and tracker.steps == 4 and tracker.stationary == 0
    cov = b2.cov_4x4[-1]
    assert np.all(np.linalg.eigvalsh(cov) > 0)
    assert cov[0, 0] > 4e-4  # heading uncertainty of earlier steps spreads into position
    assert cov[3, 3] == pytest.approx(4e-4, rel=1e-6)
    assert tracker.update([12], rows[[2]].tobytes()) is None  # stale resend


def test_stepwise_standing_still_is_not_a_step() -> None:
    dx = np.array([[0.01, 0.0, 0.0], [0.7, 0.0, 0.0], [0.0, 0.0, 0.0]])
    rows = stepwise.encode_payloads(dx, np.array([0.3, 0.0, 0.0]), np.zeros((3, 4, 4)), np.arange(3))
    tracker = stepwise.StepwiseTracker()
    batch = tracker.update([1, 2, 3], rows.tobytes())
    assert batch is not None
    assert batch.is_step.tolist() == [False, True, False]
    assert (tracker.steps, tracker.stationary) == (1, 2)
    assert batch.heading_rad[-1] == pytest.approx(0.3)  # a turn on the spot still counts
    np.testing.assert_allclose(batch.pos_n_m[-1], [0.01 + 0.7 * math.cos(0.3), 0.7 * math.sin(0.3), 0], atol=1e-6)


def test_stepwise_counter_wraps() -> None:
    rows = stepwise.encode_payloads(np.ones((3, 3)), np.zeros(3), np.zeros((3, 4, 4)), np.arange(3))
    batch = stepwise.StepwiseTracker().update([65535, 0, 1], rows.tobytes())
    assert batch is not None and batch.counter.tolist() == [65535, 65536, 65537]


def test_extension_round_trips() -> None:
    t = np.array([1, 2, 3, 2**32 + 5])
    tof = extensions.encode_tof(t, np.array([0, 1, 2, 0]), np.array([0.123, np.nan, 1.5, 0.2]), np.array([0, 1, 0, 4]))
    assert tof.shape == (4, extensions.TOF_PAYLOAD_LEN)
    assert tof[0].tobytes() == h("E1 00000001 00 007B 00")
    arr = extensions.decode_tof(tof.tobytes())
    np.testing.assert_allclose(arr.range_m, [0.123, np.nan, 1.5, np.nan])
    assert arr.status.tolist() == [0, 1, 0, 4] and arr.ticks.tolist() == [1, 2, 3, 5]
    baro = extensions.encode_baro(t[:2], np.array([101325.0, np.nan]), np.array([21.5, 20.0]))
    assert baro[0].tobytes() == h("E2 00000001 009A9C14 0866")
    barr = extensions.decode_baro(baro.tobytes())
    np.testing.assert_allclose(barr.pressure_pa, [101325.0, np.nan])
    np.testing.assert_allclose(barr.temperature_c, [21.5, np.nan])
    assert extensions.extension_kind(tof[0].tobytes()) == extensions.STATE_TOF
    assert extensions.extension_kind(baro[0].tobytes()) == extensions.STATE_BARO
    assert extensions.extension_kind(bytes(9)) is None
    with pytest.raises(ValueError, match="start with 0xE1"):
        extensions.decode_tof(bytes(9))


# --- properties: random payloads never crash a decoder; bad checksums never reach one ---------------

_ALL_INS = ins_states.InsLayout(ins_states.INS_STATE_IDS)
DECODERS = {  # name: (payload length, type byte or None, decoder)
    "raw4": (52, None, lambda b: raw_imu.decode_payloads(b, RawImuLayout((0, 1, 2, 3)))),
    "raw2": (32, None, lambda b: raw_imu.decode_payloads(b, RawImuLayout((0, 1), temperature=True))),
    "ins": (_ALL_INS.payload_len, None, lambda b: ins_states.decode_payloads(b, _ALL_INS)),
    "steps": (58, None, stepwise.decode_payloads),
    "tof": (9, extensions.STATE_TOF, extensions.decode_tof),
    "baro": (11, extensions.STATE_BARO, extensions.decode_baro),
}


@settings(max_examples=int(os.environ.get("FOOTNAV_FUZZ_EXAMPLES", "150")), deadline=None)
@given(kind=st.sampled_from(sorted(DECODERS)), data=st.data())
def test_random_payloads_never_crash(kind: str, data: st.DataObject) -> None:
    size, type_byte, decode = DECODERS[kind]
    n = data.draw(st.integers(0, 4))
    records = [data.draw(st.binary(min_size=size, max_size=size)) for _ in range(n)]
    if type_byte is not None:
        records = [bytes([type_byte]) + r[1:] for r in records]
    payload = b"".join(records)
    with np.errstate(all="ignore"):
        decode(payload)
    if kind == "steps" and n:
        with np.errstate(all="ignore"):
            stepwise.StepwiseTracker().update(list(range(n)), payload)
    bad = payload + b"\x00"
    with pytest.raises(ValueError):
        decode(bad)


@settings(max_examples=int(os.environ.get("FOOTNAV_FUZZ_EXAMPLES", "150")), deadline=None)
@given(kind=st.sampled_from(sorted(DECODERS)), data=st.data())
def test_a_packet_with_a_bad_checksum_yields_nothing(kind: str, data: st.DataObject) -> None:
    size, _, _ = DECODERS[kind]
    payload = data.draw(st.binary(min_size=size, max_size=size))
    pkt = bytearray(data_packet(data.draw(st.integers(0, 0xFFFF)), payload))
    pkt[data.draw(st.integers(-2, -1))] ^= data.draw(st.integers(1, 255))
    framer = Framer(accepted_lengths={size})
    assert framer.feed(bytes(pkt)) == []
    assert framer.stats.checksum_errors == 1
