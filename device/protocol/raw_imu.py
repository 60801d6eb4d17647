"""Raw per-IMU register packets (command 0x28, any subset of up to 32 IMUs), vectorised.

Payload, all fields big-endian, states in ascending state-ID order (protocol-openshoe.md 4.2, 5.4)::

    ts uint32 (64 MHz ticks)
    | for each IMU i in the mask, ascending:  ax ay az gx gy gz  int16   (states 0x40+i)
    | if mode bit 0x80, for each IMU:        temperature      int16   (states 0x60+i)
    | if mode bit 0x08, for each IMU:        mx my mz         int16   (states 0x90+i)

Packet = 4 + (4 + 12·n) + 2 bytes without the optional blocks: 58 bytes for four IMUs. Payload
lengths 16, 28, 40, 52 for 1–4 IMUs: the two-IMU length 28 equals the normal-IMU (0x40) payload,
so a host must decode by the mode it started, not by length alone.

Scale for MPU-9150/6500-class parts as the firmware configures them (±16 g, ±2000 °/s;
``hcarlsso/openshoe-framework:src/internal_interfaces/MPU9150_interface.c``):
acc = raw / 2048 g, gyro = raw / 16.4 °/s (``lior88/ProjectB:Recordings/log_mimu_data.m``).
Temperature and magnetometer registers are passed on as raw counts: their scale depends on the part.

The dual-IMU board is this stream with mask 0b11 (:data:`DUAL_IMU_MASK`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np
from footnav.device.protocol import commands as protocol
from numpy.typing import NDArray

STANDARD_GRAVITY_MPS2: Final = 9.80665
ACC_LSB_PER_G: Final = 2048.0
GYR_LSB_PER_DPS: Final = 16.4
ACC_SCALE_MPS2_PER_LSB: Final = STANDARD_GRAVITY_MPS2 / ACC_LSB_PER_G
GYR_SCALE_RADPS_PER_LSB: Final = math.radians(1.0) / GYR_LSB_PER_DPS
TEMP_LSB_PER_DEGC: Final = 333.87
"""MPU-6500 temperature sensitivity, LSB/°C (datasheet PS-MPU-6500A-01: TEMP_degC = TEMP_OUT / 333.87 + 21)."""
TEMP_OFFSET_DEGC: Final = 21.0
"""MPU-6500 temperature at TEMP_OUT = 0 (room-temperature offset 0 LSB), °C."""
DUAL_IMU_MASK: Final = 0b11
"""The dual-IMU board: IMUs 0 and 1 on one PCB, a fixed 1–2 cm apart."""


def mask_to_ids(imu_mask: int) -> tuple[int, ...]:
    """IMU indices whose bits are set in ``imu_mask``, ascending."""
    return tuple(i for i in range(32) if imu_mask >> i & 1)


def ids_to_mask(imu_ids: tuple[int, ...] | list[int]) -> int:
    """Inverse of :func:`mask_to_ids`."""
    mask = 0
    for i in imu_ids:
        mask |= 1 << i
    return mask


@dataclass(frozen=True, slots=True)
class RawImuLayout:
    """Which blocks a 0x28 payload holds.

    Attributes
    ----------
    imu_ids
        IMU indices present, ascending.
    temperature
        temperature block present (mode bit 0x80).
    magnetometer
        magnetometer block present (mode bit 0x08).
    """

    imu_ids: tuple[int, ...]
    temperature: bool = False
    magnetometer: bool = False

    @classmethod
    def from_command(cls, imu_mask: int, mode: int) -> RawImuLayout:
        """The layout a unit sends after ``28 imu_mask mode``."""
        return cls(
            mask_to_ids(imu_mask),
            temperature=bool(mode & protocol.MODE_TEMPERATURE),
            magnetometer=bool(mode & protocol.MODE_MAGNETOMETER),
        )

    @property
    def n_imus(self) -> int:
        """Number of IMUs in each payload."""
        return len(self.imu_ids)

    @property
    def dtype(self) -> np.dtype[np.void]:
        """Structured big-endian dtype of one payload."""
        k = self.n_imus
        fields: list[tuple[str, str] | tuple[str, str, tuple[int, ...]]] = [
            ("ts", ">u4"),
            ("imu", ">i2", (k, 6)),
        ]
        if self.temperature:
            fields.append(("temp", ">i2", (k,)))
        if self.magnetometer:
            fields.append(("mag", ">i2", (k, 3)))
        return np.dtype(fields)

    @property
    def payload_len(self) -> int:
        """Payload bytes: 4 + 12 k (+ 2 k temperature) (+ 6 k magnetometer)."""
        return int(self.dtype.itemsize)


@dataclass(frozen=True, slots=True)
class RawImuArrays:
    """Decoded payloads (struct of arrays), n samples of k IMUs.

    Attributes
    ----------
    ticks
        (n,) uint32 64 MHz timestamps, wrapping.
    acc_b_mps2
        (n, k, 3) specific force per IMU, that IMU's axes, m/s².
    gyr_b_radps
        (n, k, 3) angular rate per IMU, rad/s.
    temperature_raw
        (n, k) raw temperature registers, or None.
    mag_raw
        (n, k, 3) raw magnetometer registers, or None.
    """

    ticks: NDArray[np.uint32]
    acc_b_mps2: NDArray[np.float64]
    gyr_b_radps: NDArray[np.float64]
    temperature_raw: NDArray[np.int16] | None
    mag_raw: NDArray[np.int16] | None


@dataclass(frozen=True, slots=True)
class RawImuBatch:
    """Raw IMU samples of one read (duplicates dropped), in SI units.

    Attributes
    ----------
    imu_ids
        (k,) IMU indices of axis 1, ascending.
    t_s
        (n,) device time, s, unwrapped from the 64 MHz counter.
    acc_b_mps2
        (n, k, 3) specific force per IMU, m/s².
    gyr_b_radps
        (n, k, 3) angular rate per IMU, rad/s.
    temperature_raw
        (n, k) raw temperature counts, or None.
    mag_raw
        (n, k, 3) raw magnetometer counts, or None.
    counter
        (n,) unwrapped package numbers.
    host_ns
        (n,) host receive time of the read, ``time.monotonic_ns()``.
    """

    imu_ids: tuple[int, ...]
    t_s: NDArray[np.float64]
    acc_b_mps2: NDArray[np.float64]
    gyr_b_radps: NDArray[np.float64]
    temperature_raw: NDArray[np.int16] | None
    mag_raw: NDArray[np.int16] | None
    counter: NDArray[np.int64]
    host_ns: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def decode_payloads(payloads: bytes | bytearray | memoryview, layout: RawImuLayout) -> RawImuArrays:
    """Decode the concatenation of n payloads of ``layout`` (one ``np.frombuffer``).

    Raises
    ------
    ValueError
        the length is not a multiple of the payload length.
    """
    size = layout.payload_len
    if len(payloads) % size:
        raise ValueError(f"raw-IMU payloads of {layout.n_imus} IMU(s) are {size} bytes each; got {len(payloads)}")
    rec = np.frombuffer(payloads, dtype=layout.dtype)
    regs = rec["imu"].astype(np.float64)
    return RawImuArrays(
        ticks=rec["ts"].astype(np.uint32),
        acc_b_mps2=regs[:, :, 0:3] * ACC_SCALE_MPS2_PER_LSB,
        gyr_b_radps=regs[:, :, 3:6] * GYR_SCALE_RADPS_PER_LSB,
        temperature_raw=rec["temp"].astype(np.int16) if layout.temperature else None,
        mag_raw=rec["mag"].astype(np.int16) if layout.magnetometer else None,
    )


def temperature_c(temperature_raw: NDArray[np.integer]) -> NDArray[np.float64]:
    """Raw temperature registers -> °C (MPU-6500 scale, :data:`TEMP_LSB_PER_DEGC`)."""
    return np.asarray(temperature_raw, dtype=np.float64) / TEMP_LSB_PER_DEGC + TEMP_OFFSET_DEGC


def temperature_registers(temp_c: NDArray[np.floating]) -> NDArray[np.int16]:
    """°C -> raw temperature registers, rounded and saturated (inverse of :func:`temperature_c`)."""
    raw = np.rint((np.asarray(temp_c, dtype=np.float64) - TEMP_OFFSET_DEGC) * TEMP_LSB_PER_DEGC)
    return np.clip(raw, -32768, 32767).astype(np.int16)


def si_to_registers(acc_b_mps2: NDArray[np.floating], gyr_b_radps: NDArray[np.floating]) -> NDArray[np.int16]:
    """(…, 3) acc and gyro in SI -> (…, 6) int16 registers, rounded and saturated like the sensor."""
    acc = np.rint(np.asarray(acc_b_mps2, dtype=np.float64) / ACC_SCALE_MPS2_PER_LSB)
    gyr = np.rint(np.asarray(gyr_b_radps, dtype=np.float64) / GYR_SCALE_RADPS_PER_LSB)
    regs = np.concatenate([acc, gyr], axis=-1)
    return np.clip(regs, -32768, 32767).astype(np.int16)


def encode_payloads(
    layout: RawImuLayout,
    ticks: NDArray[np.integer],
    registers: NDArray[np.integer],
    temperature_raw: NDArray[np.integer] | None = None,
    mag_raw: NDArray[np.integer] | None = None,
) -> NDArray[np.uint8]:
    """Encode n payloads as an (n, L) byte matrix (for the emulator; frame with ``frame_payload_rows``).

    Parameters
    ----------
    layout
        what the payload holds.
    ticks
        (n,) 64 MHz timestamps, taken modulo 2**32.
    registers
        (n, k, 6) int16 registers (ax ay az gx gy gz) of the layout's IMUs.
    temperature_raw
        (n, k) when ``layout.temperature`` (zeros if None).
    mag_raw
        (n, k, 3) when ``layout.magnetometer`` (zeros if None).
    """
    n = len(ticks)
    rec = np.zeros(n, dtype=layout.dtype)
    rec["ts"] = np.asarray(ticks, dtype=np.int64) % (1 << 32)
    rec["imu"] = registers
    if layout.temperature and temperature_raw is not None:
        rec["temp"] = temperature_raw
    if layout.magnetometer and mag_raw is not None:
        rec["mag"] = mag_raw
    return rec.view(np.uint8).reshape(n, layout.payload_len)
