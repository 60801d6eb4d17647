"""Raw binary logs of a unit's stream, as vendor loggers write them: the emulated unit's own bytes
(ACKs included, or removed, with garbage between packets), read by ``export`` at the rate the unit's
clock gives; bad bytes are counted and skipped, a file that is no log says what was expected."""

from __future__ import annotations

import asyncio
import contextlib
import csv
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.files import vendor_log
from footnav.device.files.recordings import detect_format, load_recording
from footnav.device.modes import RawImuMode
from footnav.device.protocol import imu as normal_imu
from footnav.device.protocol.commands import data_packet
from footnav.device.protocol.framer import DataPacket, Framer
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.errors import InputFormatError
from hypothesis import given, settings
from hypothesis import strategies as st

N_IMUS = 4


@pytest.fixture(scope="module")
def walk() -> GaitTruth:
    return simulate_walk("rectangle", 30.0, rate_hz=1000.0, seed=1)


@pytest.fixture(scope="module")
def raw4_log(walk: GaitTruth) -> bytes:
    """What a vendor logger saves of a four-IMU unit's raw output 0x28 at 500 Hz (mask 0x0F): every
    byte the emulated unit sent, its ACKs included."""
    signals = [corrupt(walk.acc_b_mps2, walk.gyr_b_radps, 1000.0, IMU_GRADES["mpu6500x4"], seed=i) for i in range(4)]
    acc = np.stack([s[0] for s in signals], axis=1)
    gyr = np.stack([s[1] for s in signals], axis=1)

    async def log() -> bytes:
        with PtyShoeServer(walk.t_s, acc[:, 0], gyr[:, 0], speed=math.inf, imu_acc_b_mps2=acc,
                           imu_gyr_b_radps=gyr) as server:  # fmt: skip
            async with await OpenShoeUnit.open_serial(server.port) as unit:
                await unit.start(RawImuMode(imu_mask=0x0F, rate_divider_log2=1))
                n = 0
                async with asyncio.timeout(60), contextlib.aclosing(unit.batches()) as stream:
                    async for batch in stream:
                        n += len(batch)
                        if n >= walk.t_s.size // 2:
                            break
                await unit.stop()
            return server.sent_bytes

    return asyncio.run(log())


def _export(path: Path, out: Path) -> np.ndarray:
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "export", str(path), "-o", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "mimu-log recording" in proc.stdout
    with out.open() as f:
        return np.array(list(csv.reader(f))[1:], dtype=float)


def test_a_raw_four_imu_log_exports_at_the_clocks_rate(tmp_path: Path, walk: GaitTruth, raw4_log: bytes) -> None:
    path = tmp_path / "MIMU4444_log.bin"
    path.write_bytes(raw4_log)
    rec = load_recording(path)
    assert rec.format == "mimu-log" and rec.rate_hz == 500.0 and len(rec) == walk.t_s.size // 2
    assert "raw registers 0x28 of 4 IMU(s), averaged" in rec.notes[0]
    rows = _export(path, tmp_path / "track.csv")
    assert rows.shape[0] == walk.t_s.size // 2  # every sample navigated (the walk starts still)
    np.testing.assert_allclose(np.diff(rows[:, 0]), 0.002, atol=1e-6)
    end = walk.pos_n_m[round(rows[-1, 0] * 1000.0)]
    assert np.linalg.norm(rows[-1, 1:4] - end) < 0.002 * walk.distance_m  # 0.01 % measured


def test_without_acks_and_with_garbage_between_packets_the_same_track(tmp_path: Path, raw4_log: bytes) -> None:
    framer = Framer()
    packets = [f for f in framer.feed(raw4_log) if isinstance(f, DataPacket)]
    rng = np.random.default_rng(4)
    noisy = bytearray(b"\x00\xaa\xa0garbage\r\n")
    for p in packets:
        noisy += data_packet(p.number, p.payload)
        if rng.random() < 0.05:
            noisy += bytes(rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8))
    for p in packets[-4:-1]:  # a resent run of three, as lossless mode resends: dropped whole
        noisy += data_packet(p.number, p.payload)
    noisy += data_packet(packets[-1].number, packets[-1].payload)
    clean_path, noisy_path = tmp_path / "acks.bin", tmp_path / "noisy.bin"
    clean_path.write_bytes(raw4_log)
    noisy_path.write_bytes(bytes(noisy))
    rec = load_recording(noisy_path)
    assert any("bytes between packets skipped" in n for n in rec.notes)
    assert any("4 resent or late packets dropped" in n for n in rec.notes)
    assert np.diff(rec.t_s).max() < 0.0021 and rec.rate_hz == 500.0  # no backward tick read as a wrap
    np.testing.assert_array_equal(
        _export(noisy_path, tmp_path / "noisy.csv"), _export(clean_path, tmp_path / "clean.csv")
    )


def test_a_calibrated_imu_log_is_read_as_0x40(tmp_path: Path, walk: GaitTruth) -> None:
    n = 4000
    ticks = normal_imu.seconds_to_ticks(walk.t_s[:n], tick0=123)
    data = normal_imu.encode_packets(np.arange(n) + 1, ticks, walk.acc_b_mps2[:n], walk.gyr_b_radps[:n])
    path = tmp_path / "oblu.log"
    path.write_bytes(data)
    assert detect_format(path) == "mimu-log"
    rec = load_recording(path)
    assert rec.rate_hz == 1000.0 and len(rec) == n and "calibrated IMU output 0x40" in rec.notes[0]
    np.testing.assert_allclose(rec.acc_b_mps2, walk.acc_b_mps2[:n].astype(np.float32))


def test_a_file_that_is_no_log_says_what_was_expected(tmp_path: Path) -> None:
    path = tmp_path / "few.bin"
    path.write_bytes(b"".join(data_packet(k, bytes(28)) for k in range(5)))  # framed, but too few
    with pytest.raises(InputFormatError, match="5 data packets found; expected a raw log of an OpenShoe"):
        load_recording(path, "mimu-log")
    odd = tmp_path / "odd.bin"
    odd.write_bytes(b"".join(data_packet(k, bytes(10)) for k in range(40)))
    with pytest.raises(InputFormatError, match="10-byte payloads, of no output mode footnav reads"):
        load_recording(odd, "mimu-log")


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_mutated_logs_read_or_name_what_was_expected(
    data: st.DataObject, tmp_path_factory: pytest.TempPathFactory
) -> None:
    t = np.arange(300) / 250.0
    acc = np.tile([0.0, 0.0, 9.81], (300, 1))
    base = normal_imu.encode_packets(np.arange(300), normal_imu.seconds_to_ticks(t, 0), acc, np.zeros((300, 3)))
    blob = bytearray(base)
    for _ in range(data.draw(st.integers(0, 20))):
        at = data.draw(st.integers(0, len(blob) - 1))
        blob[at] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(blob)))
    path = tmp_path_factory.mktemp("fuzz") / "log.bin"
    path.write_bytes(bytes(blob[:cut]))
    try:
        rec = load_recording(path, "mimu-log")
    except InputFormatError as exc:
        assert "expected" in str(exc)
        return
    assert len(rec) >= vendor_log.MIN_PACKETS
    assert np.median(np.diff(rec.t_s)) == pytest.approx(1 / 250.0)  # the unit's clock, corrupt ticks or not
