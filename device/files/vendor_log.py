"""Raw binary logs of a unit's stream, as vendor loggers write them (GT Silicon's MIMUscope, its Python
calibration logger, the Matlab logger of ``lior88/ProjectB``): the device -> host bytes as received,
with or without the units' ACKs, possibly with other bytes between packets.

The packets are found by the protocol's own framing (:class:`footnav.device.protocol.framer.Framer`:
header, length, checksum; anything else is skipped and counted), and the output mode is told by the
payload length the stream carries most:

- 28 bytes whose float32 fields read as plausible specific force: the calibrated IMU output 0x40/0x41
  (``footnav.device.protocol.imu``);
- 4 + 12 k bytes (4 + 14 k with the temperature block): the raw registers 0x28 of k IMUs, k = 1..4
  (``footnav.device.protocol.raw_imu``), fused into one IMU as OpenShoe's array firmware fuses them:
  the mean of the k IMUs in SI units (registers times the per-IMU scale), which assumes their axes are
  aligned, as on the MIMU boards.

A package number is taken the first time the count moves past it (resends and late packets are
dropped); the sample rate is the unit's clock's
(:func:`footnav.device.protocol.imu.clock_rate_hz`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

import numpy as np
from footnav.device.protocol import imu as normal_imu
from footnav.device.protocol import raw_imu
from footnav.device.protocol.framer import DataPacket, Framer
from footnav.device.protocol.imu import TickUnwrapper, clock_rate_hz
from footnav.pipeline.errors import InputFormatError
from numpy.typing import NDArray

F64 = NDArray[np.float64]

EXPECTED: Final = "a raw log of an OpenShoe/MIMU unit's stream (calibrated IMU 0x40 or raw IMUs 0x28)"
MIN_PACKETS: Final = 16
"""Fewer checksum-valid packets than this are not a log."""
NORMAL_IMU_PAYLOAD: Final = 28
PLAUSIBLE_REST_MPS2: Final = (3.0, 30.0)
"""Median |specific force| of a 0x40 stream (gravity and walking); raw int16 bytes read as float32
fall far outside."""


def framed_packets(data: bytes) -> tuple[list[DataPacket], int]:
    """The checksum-valid data packets of ``data``, and the bytes that were not part of any frame."""
    framer = Framer()
    frames = framer.feed(data)
    packets = [f for f in frames if isinstance(f, DataPacket)]
    return packets, framer.stats.bytes_skipped + framer.buffered


def looks_like_log(head: bytes) -> bool:
    """Whether ``head`` (the start of a file) holds data packets of the protocol back to back."""
    packets, _ = framed_packets(head)
    return len(packets) >= 4 and len({len(p.payload) for p in packets}) <= 2


def _unique_in_order(numbers: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Packets to keep: each package number (uint16 as sent) the first time the count moves past it.

    The numbers are unwrapped by their signed steps modulo 2**16; a packet is kept when its number is
    beyond every number before it, so a resent run (``1 2 3 4 5 2 3 4 6``) and a late packet are
    dropped whole and the kept packets stay in their order."""
    steps = (np.diff(numbers, prepend=numbers[0]) + 32768) % 65536 - 32768
    unwrapped = np.cumsum(steps)
    before = np.concatenate([[unwrapped[0] - 1], np.maximum.accumulate(unwrapped)[:-1]])
    keep: NDArray[np.bool_] = unwrapped > before
    return keep


def _normal_imu(payloads: bytes) -> tuple[NDArray[np.uint32], F64, F64] | None:
    arrays = normal_imu.decode_payloads(payloads)
    with np.errstate(invalid="ignore", over="ignore"):
        norm = np.linalg.norm(arrays.acc_b_mps2.astype(np.float64), axis=1)
    median = float(np.nanmedian(norm)) if np.isfinite(norm).any() else np.nan
    lo, hi = PLAUSIBLE_REST_MPS2
    if not lo < median < hi:
        return None
    return arrays.ticks, arrays.acc_b_mps2.astype(np.float64), arrays.gyr_b_radps.astype(np.float64)


def _raw_layout(length: int) -> raw_imu.RawImuLayout | None:
    for k in range(1, 5):
        for temperature in (False, True):
            layout = raw_imu.RawImuLayout(tuple(range(k)), temperature=temperature)
            if layout.payload_len == length:
                return layout
    return None


def _raw_imus(payloads: bytes, layout: raw_imu.RawImuLayout) -> tuple[NDArray[np.uint32], F64, F64]:
    arrays = raw_imu.decode_payloads(payloads, layout)  # SI units, per IMU
    return arrays.ticks, arrays.acc_b_mps2.mean(axis=1), arrays.gyr_b_radps.mean(axis=1)


def decode_log(data: bytes, name: str) -> tuple[F64, F64, F64, list[str]]:
    """(t_s (n,), acc (n, 3) m/s², gyr (n, 3) rad/s, notes) of a log's bytes.

    Raises
    ------
    InputFormatError
        too few packets, or a payload length of no mode footnav decodes.
    """
    packets, skipped = framed_packets(data)
    if len(packets) < MIN_PACKETS:
        raise InputFormatError(f"{name}: {len(packets)} data packets found; expected {EXPECTED}")
    lengths, counts = np.unique([len(p.payload) for p in packets], return_counts=True)
    length = int(lengths[np.argmax(counts)])
    stream = [p for p in packets if len(p.payload) == length]
    numbers = np.array([p.number for p in stream], dtype=np.int64)
    keep = _unique_in_order(numbers)
    stream = [p for p, k in zip(stream, keep, strict=True) if k]
    payloads = b"".join(p.payload for p in stream)
    decoded = _normal_imu(payloads) if length == NORMAL_IMU_PAYLOAD else None
    what = "calibrated IMU output 0x40"
    if decoded is None:
        layout = _raw_layout(length)
        if layout is None:
            raise InputFormatError(
                f"{name}: its packets carry {length}-byte payloads, of no output mode footnav reads; "
                f"expected {EXPECTED}"
            )
        decoded = _raw_imus(payloads, layout)
        what = f"raw registers 0x28 of {layout.n_imus} IMU(s), averaged"
    ticks, acc, gyr = decoded
    t_s = TickUnwrapper().update(ticks)
    dropped = int(np.count_nonzero(~keep))
    others = len(packets) - len(stream) - dropped
    notes = [f"{len(stream)} packets of the {what}"]
    notes += [f"{skipped} bytes between packets skipped"] if skipped else []
    notes += [f"{others} packets of other lengths ignored"] if others else []
    notes += [f"{dropped} resent or late packets dropped"] if dropped else []
    return t_s - t_s[0], acc, gyr, notes


def load_mimu_log(path: Path) -> tuple[F64, F64, F64, float, list[str]]:
    """(t_s, acc, gyr, rate_hz, notes) of the log at ``path`` (see :func:`decode_log`).

    Raises
    ------
    InputFormatError
        the file cannot be read or is not such a log.
    """
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputFormatError(f"cannot read {path}: {exc.strerror}") from None
    t_s, acc, gyr, notes = decode_log(data, str(path))
    rate_hz = clock_rate_hz(t_s)
    if rate_hz is None:
        raise InputFormatError(f"{path}: its packets' clock gives no sample rate; expected {EXPECTED}")
    return t_s, acc, gyr, rate_hz, notes
