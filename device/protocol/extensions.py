"""footnav's extension states for units whose papers publish no protocol: ToF ranges and a barometer.

For firmware authors: these fit the OpenShoe framing unchanged (``AA pkt_hi pkt_lo N payload chk``,
protocol-openshoe.md 4.1), share the interface's package counter and lossless queue, and are switched
with the existing OUTPUT_STATE command, so a 2015-firmware parser needs no new command ID::

    20 E1 mode chk     ToF ranges on (mode & 0x0F != 0) / off (mode & 0x0F == 0); mode 0x10 = lossless
    20 E2 mode chk     barometer on / off

Both are **event-driven**: one packet per completed measurement, sent on its own (never concatenated
with other states in one packet), so the rate bits only mean on/off. Each payload starts with its state
ID as a type byte and has a length no standard output uses (normal IMU 28, raw IMU 16/28/40/52 and
with temperature/magnetometer 18–84, INS 4–224 in multiples of 4, SWDR 58: all even; MCU id 15),
so a host can tell them apart by (N, first byte) even when they are interleaved with another stream.

State 0xE1 TOF_RANGE, N = 9, big-endian::

    off  size  field
    0    1     0xE1
    1    4     ts: uint32, 64 MHz ticks (the IMU_TS clock) when the measurement completed
    5    1     sensor index: 0, 1, 2 (three sensors, ~33 Hz each, staggered in time)
    6    2     range: uint16, mm (0xFFFF when there is none)
    8    1     status: 0 valid, 1 time-out, 2 no target / out of range, 3 weak signal, 4 sensor error

State 0xE2 BARO, N = 11, big-endian::

    off  size  field
    0    1     0xE2
    1    4     ts: uint32, 64 MHz ticks
    5    4     pressure: uint32, 0.01 Pa; 0 = no valid reading (sensor error)
    9    2     temperature: int16, 0.01 °C

Host side, ranges are converted to metres and pressure/temperature to Pa/°C; a ToF reading whose
status is not 0, or a pressure of 0, is NaN (the status is kept), never a number that could be
mistaken for a measurement. Both lengths are odd: every standard output except the MCU id (15) has an
even payload length.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

STATE_TOF: Final = 0xE1
STATE_BARO: Final = 0xE2
TOF_PAYLOAD_LEN: Final = 9
BARO_PAYLOAD_LEN: Final = 11
TOF_SENSORS: Final = 3
TOF_NO_RANGE: Final = 0xFFFF

TOF_VALID: Final = 0
TOF_TIMEOUT: Final = 1
TOF_NO_TARGET: Final = 2
TOF_WEAK_SIGNAL: Final = 3
TOF_SENSOR_ERROR: Final = 4

TOF_DTYPE: Final = np.dtype([("type", "u1"), ("ts", ">u4"), ("sensor", "u1"), ("range", ">u2"), ("status", "u1")])
BARO_DTYPE: Final = np.dtype([("type", "u1"), ("ts", ">u4"), ("pressure", ">u4"), ("temp", ">i2")])

EXTENSION_LENGTHS: Final = {STATE_TOF: TOF_PAYLOAD_LEN, STATE_BARO: BARO_PAYLOAD_LEN}


def extension_kind(payload: bytes) -> int | None:
    """The extension state a payload carries (:data:`STATE_TOF` / :data:`STATE_BARO`), or None."""
    if payload and EXTENSION_LENGTHS.get(payload[0]) == len(payload):
        return int(payload[0])
    return None


@dataclass(frozen=True, slots=True)
class TofArrays:
    """Decoded ToF payloads: ticks (n,) uint32, sensor (n,), range_m (n,) (NaN unless valid), status (n,)."""

    ticks: NDArray[np.uint32]
    sensor: NDArray[np.int64]
    range_m: NDArray[np.float64]
    status: NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class BaroArrays:
    """Decoded barometer payloads: ticks (n,), pressure_pa (n,), temperature_c (n,) (NaN if invalid)."""

    ticks: NDArray[np.uint32]
    pressure_pa: NDArray[np.float64]
    temperature_c: NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class TofBatch:
    """ToF range readings of one read, in arrival order.

    Attributes
    ----------
    t_s
        (n,) device time of each measurement, s.
    sensor
        (n,) sensor index 0..2.
    range_m
        (n,) range, m; NaN where status != 0.
    status
        (n,) status byte (see the module docstring).
    counter
        (n,) unwrapped package numbers.
    host_ns
        (n,) host receive time of the read.
    """

    t_s: NDArray[np.float64]
    sensor: NDArray[np.int64]
    range_m: NDArray[np.float64]
    status: NDArray[np.uint8]
    counter: NDArray[np.int64]
    host_ns: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True, slots=True)
class BaroBatch:
    """Barometer readings of one read: t_s (n,) s, pressure_pa (n,), temperature_c (n,) (NaN if invalid)."""

    t_s: NDArray[np.float64]
    pressure_pa: NDArray[np.float64]
    temperature_c: NDArray[np.float64]
    counter: NDArray[np.int64]
    host_ns: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def _records(payloads: bytes | bytearray | memoryview, dtype: np.dtype[np.void], state: int) -> NDArray[np.void]:
    if len(payloads) % dtype.itemsize:
        raise ValueError(f"state 0x{state:02X} payloads are {dtype.itemsize} bytes each; got {len(payloads)}")
    rec = np.frombuffer(payloads, dtype=dtype)
    if np.any(rec["type"] != state):
        raise ValueError(f"state 0x{state:02X} payloads start with 0x{state:02X}")
    return rec


def decode_tof(payloads: bytes | bytearray | memoryview) -> TofArrays:
    """Decode n concatenated 9-byte ToF payloads.

    Raises
    ------
    ValueError
        wrong total length or a payload whose type byte is not 0xE1.
    """
    rec = _records(payloads, TOF_DTYPE, STATE_TOF)
    status = rec["status"].astype(np.uint8)
    rng = rec["range"].astype(np.float64) / 1000.0
    ok = (status == TOF_VALID) & (rec["range"] != TOF_NO_RANGE)
    return TofArrays(
        ticks=rec["ts"].astype(np.uint32),
        sensor=rec["sensor"].astype(np.int64),
        range_m=np.where(ok, rng, np.nan),
        status=status,
    )


def decode_baro(payloads: bytes | bytearray | memoryview) -> BaroArrays:
    """Decode n concatenated 11-byte barometer payloads.

    Raises
    ------
    ValueError
        wrong total length or a payload whose type byte is not 0xE2.
    """
    rec = _records(payloads, BARO_DTYPE, STATE_BARO)
    ok = rec["pressure"] != 0
    return BaroArrays(
        ticks=rec["ts"].astype(np.uint32),
        pressure_pa=np.where(ok, rec["pressure"].astype(np.float64) / 100.0, np.nan),
        temperature_c=np.where(ok, rec["temp"].astype(np.float64) / 100.0, np.nan),
    )


def encode_tof(
    ticks: NDArray[np.integer],
    sensor: NDArray[np.integer],
    range_m: NDArray[np.floating],
    status: NDArray[np.integer],
) -> NDArray[np.uint8]:
    """(n, 9) ToF payloads (for the emulator); a NaN range or a non-zero status sends 0xFFFF."""
    n = len(ticks)
    rec = np.zeros(n, dtype=TOF_DTYPE)
    rec["type"] = STATE_TOF
    rec["ts"] = np.asarray(ticks, dtype=np.int64) % (1 << 32)
    rec["sensor"] = sensor
    rng = np.asarray(range_m, dtype=np.float64)
    st = np.asarray(status, dtype=np.uint8)
    good = np.isfinite(rng) & (st == TOF_VALID)
    mm = np.clip(np.rint(np.where(good, rng, 0.0) * 1000.0), 0, TOF_NO_RANGE - 1)
    rec["range"] = np.where(good, mm, TOF_NO_RANGE)
    rec["status"] = st
    return rec.view(np.uint8).reshape(n, TOF_PAYLOAD_LEN)


def encode_baro(
    ticks: NDArray[np.integer],
    pressure_pa: NDArray[np.floating],
    temperature_c: NDArray[np.floating],
) -> NDArray[np.uint8]:
    """(n, 11) barometer payloads (for the emulator); a NaN pressure sends 0 (invalid)."""
    n = len(ticks)
    rec = np.zeros(n, dtype=BARO_DTYPE)
    rec["type"] = STATE_BARO
    rec["ts"] = np.asarray(ticks, dtype=np.int64) % (1 << 32)
    p = np.asarray(pressure_pa, dtype=np.float64)
    rec["pressure"] = np.where(np.isfinite(p), np.clip(np.rint(np.nan_to_num(p) * 100.0), 1, 2**32 - 1), 0)
    t = np.nan_to_num(np.asarray(temperature_c, dtype=np.float64))
    rec["temp"] = np.clip(np.rint(t * 100.0), -32768, 32767)
    return rec.view(np.uint8).reshape(n, BARO_PAYLOAD_LEN)
