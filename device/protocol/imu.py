"""Normal-IMU packets (commands 0x40/0x41), vectorised; device tick and packet-counter unwrapping.

34-byte packet, all fields big-endian (protocol-openshoe.md sections 4.1, 4.2 and 5.3)::

    AA | pkt# uint16 | N = 0x1C | ts uint32 (64 MHz ticks) | ax ay az float32 [m/s²]
       | gx gy gz float32 [rad/s] | chk uint16

Sources: ``hcarlsso/openshoe-framework:src/external_interfaces/response_functions.c`` (``normal_imu``),
``oblu-iot/ObluScope-Java:src/io/oblu/commn/ParseNormalImu.java`` (DATA_LEN = 34, payload 28).
Encoding many packets at once is for the emulator; decoding many payloads at once is for the host.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from footnav.device.protocol.sequence import CounterTracker  # noqa: F401 (its former home)
from footnav.pipeline.samples import diff_after
from numpy.typing import NDArray

TICK_HZ: Final = 64e6
"""IMU_TS is the CPU cycle counter at 64 MHz (``conf_clock.h`` CLOCK_FREQ); it wraps every ≈67.1 s."""
TICK_WRAP: Final = 1 << 32
COUNTER_WRAP: Final = 1 << 16

PAYLOAD_LEN: Final = 28
PACKET_LEN: Final = PAYLOAD_LEN + 6

PAYLOAD_DTYPE: Final = np.dtype([("ts", ">u4"), ("acc", ">f4", (3,)), ("gyr", ">f4", (3,))])
"""One 28-byte payload."""
PACKET_DTYPE: Final = np.dtype(
    [("sync", "u1"), ("number", ">u2"), ("length", "u1"), ("payload", PAYLOAD_DTYPE), ("chk", ">u2")]
)
"""One whole 34-byte packet."""


@dataclass(frozen=True, slots=True)
class NormalImuArrays:
    """Decoded payloads (struct of arrays).

    Attributes
    ----------
    ticks
        (n,) uint32 device timestamps, 64 MHz ticks, wrapping.
    acc_b_mps2
        (n, 3) specific force, body frame, m/s².
    gyr_b_radps
        (n, 3) angular rate, body frame, rad/s.
    """

    ticks: NDArray[np.uint32]
    acc_b_mps2: NDArray[np.float64]
    gyr_b_radps: NDArray[np.float64]


def decode_payloads(payloads: bytes | bytearray | memoryview) -> NormalImuArrays:
    """Decode the concatenation of n 28-byte payloads (one ``np.frombuffer``).

    Raises
    ------
    ValueError
        the length is not a multiple of 28.
    """
    if len(payloads) % PAYLOAD_LEN:
        raise ValueError(f"normal-IMU payloads are {PAYLOAD_LEN} bytes each; got {len(payloads)} bytes")
    rec = np.frombuffer(payloads, dtype=PAYLOAD_DTYPE)
    with np.errstate(invalid="ignore"):  # a signalling NaN (a corrupt float) stays NaN, without a warning
        return NormalImuArrays(
            ticks=rec["ts"].astype(np.uint32),
            acc_b_mps2=rec["acc"].astype(np.float64),
            gyr_b_radps=rec["gyr"].astype(np.float64),
        )


def decode_imu_rows(rows: NDArray[np.uint8]) -> NDArray[np.float64]:
    """The IMU values of m 28-byte payloads held as the rows of ``rows`` (m, 28) (a framer's run: a view
    of the bytes read): (m, 6) specific force, m/s², then angular rate, rad/s, body frame (the float32
    values, widened). Their time stamps are :attr:`footnav.device.protocol.framer.PacketRun.heads`.

    Raises
    ------
    ValueError
        the rows are not 28 bytes long.
    """
    if rows.ndim != 2 or rows.shape[1] != PAYLOAD_LEN:
        raise ValueError(f"normal-IMU payloads are {PAYLOAD_LEN} bytes each; got rows of shape {rows.shape}")
    with np.errstate(invalid="ignore"):  # a signalling NaN (a corrupt float) stays NaN, without a warning
        return rows[:, 4:].view(">f4").astype(np.float64)


def seconds_to_ticks(t_s: NDArray[np.float64], tick0: int) -> NDArray[np.uint32]:
    """Device ticks for sample times ``t_s`` (n,), s, with ``t_s[0]`` at tick ``tick0``, wrapped to uint32."""
    rel = np.rint((np.asarray(t_s, dtype=np.float64) - t_s[0]) * TICK_HZ).astype(np.int64)
    return ((rel + tick0) % TICK_WRAP).astype(np.uint32)


def encode_packets(
    numbers: NDArray[np.integer],
    ticks: NDArray[np.integer],
    acc_b_mps2: NDArray[np.floating],
    gyr_b_radps: NDArray[np.floating],
) -> bytes:
    """Encode n whole packets, headers and checksums included, as one ``bytes`` of length 34·n.

    Parameters
    ----------
    numbers
        (n,) package numbers; taken modulo 2**16.
    ticks
        (n,) timestamps in 64 MHz ticks; taken modulo 2**32.
    acc_b_mps2
        (n, 3) specific force, m/s² (sent as float32).
    gyr_b_radps
        (n, 3) angular rate, rad/s (sent as float32).
    """
    n = len(numbers)
    rec = np.empty(n, dtype=PACKET_DTYPE)
    rec["sync"] = 0xAA
    rec["number"] = np.asarray(numbers, dtype=np.int64) % COUNTER_WRAP
    rec["length"] = PAYLOAD_LEN
    rec["payload"]["ts"] = np.asarray(ticks, dtype=np.int64) % TICK_WRAP
    rec["payload"]["acc"] = acc_b_mps2
    rec["payload"]["gyr"] = gyr_b_radps
    raw = rec.view(np.uint8).reshape(n, PACKET_LEN)
    rec["chk"] = raw[:, : PACKET_LEN - 2].sum(axis=1, dtype=np.uint32) & 0xFFFF
    return rec.tobytes()


class TickUnwrapper:
    """Turns the wrapping uint32 64 MHz tick counter into increasing float64 seconds.

    Every step is taken modulo 2**32, so the result never goes backwards and a gap shorter than one
    wrap (≈67 s) is measured correctly. Time 0 is tick 0 of the first sample's wrap (the first sample
    is at ``ticks[0] / 64e6`` s). ``lior88/ProjectB:Recordings/log_mimu_data.m`` unwraps the same way.
    """

    def __init__(self) -> None:
        self._last_raw: int | None = None
        self._last_total = 0
        self.wraps = 0
        """Wraps of the counter seen so far."""

    def update(self, ticks: NDArray[np.integer]) -> NDArray[np.float64]:
        """Return (n,) device time in seconds for the next ``ticks`` (n,) in stream order."""
        raw = np.asarray(ticks, dtype=np.int64)
        if raw.size == 0:
            return np.empty(0, dtype=np.float64)
        if self._last_raw is None:
            self._last_raw = int(raw[0])
            self._last_total = int(raw[0])
        steps = diff_after(self._last_raw, raw)
        wrapped = steps < 0
        self.wraps += int(np.count_nonzero(wrapped))
        steps[wrapped] += TICK_WRAP
        total = self._last_total + np.cumsum(steps)
        self._last_raw = int(raw[-1])
        self._last_total = int(total[-1])
        return total / TICK_HZ


CLOCK_RATE_INTERVALS: Final = 16
"""Positive sample intervals :func:`clock_rate_hz` takes the rate from (the first ones of a stream)."""


def clock_rate_hz(t_s: NDArray[np.float64]) -> float | None:
    """The stream's sample rate by the unit's own clock, Hz: :data:`TICK_HZ` over the lower quartile of
    the first :data:`CLOCK_RATE_INTERVALS` positive intervals of the device times ``t_s`` (n,), s, in
    whole ticks; None before there are as many.

    The first intervals only, so a stream gives the same rate however its samples are batched. A
    repeated sample makes a zero interval, which is not counted; a lost packet makes a long one, and
    the lower quartile holds while fewer than three in four of the intervals span losses. Whole ticks
    give the nominal rate exactly (64 000 ticks: 1000 Hz; 78 125: 819.2 Hz; 2 048 000: 31.25 Hz)."""
    dt_s = np.diff(np.asarray(t_s, dtype=np.float64))
    dt_s = dt_s[dt_s > 0][:CLOCK_RATE_INTERVALS]
    if dt_s.size < CLOCK_RATE_INTERVALS:
        return None
    return TICK_HZ / max(1, round(float(np.percentile(dt_s, 25)) * TICK_HZ))


def frame_payload_rows(numbers: NDArray[np.integer], rows: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Frame m equal-length payloads at once: ``AA hi lo N payload chk_hi chk_lo`` per row.

    Parameters
    ----------
    numbers
        (m,) package numbers, taken modulo 2**16.
    rows
        (m, L) payload bytes, L <= 255.

    Returns
    -------
    NDArray[np.uint8]
        (m, L + 6) packet bytes; ``.tobytes()`` is the byte stream.
    """
    rows = np.asarray(rows, dtype=np.uint8)
    m, length = rows.shape
    if length > 0xFF:
        raise ValueError(f"a data packet holds at most 255 payload bytes, got {length}")
    out = np.empty((m, length + 6), dtype=np.uint8)
    num = np.asarray(numbers, dtype=np.int64) % COUNTER_WRAP
    out[:, 0] = 0xAA
    out[:, 1] = num >> 8
    out[:, 2] = num & 0xFF
    out[:, 3] = length
    out[:, 4 : 4 + length] = rows
    chk = out[:, : length + 4].sum(axis=1, dtype=np.uint32) & 0xFFFF
    out[:, length + 4] = chk >> 8
    out[:, length + 5] = chk & 0xFF
    return out


class SharedTickClock:
    """Unwraps 64 MHz ticks from several packet kinds sharing one device clock.

    Unlike :class:`TickUnwrapper`, each step is taken as a *signed* difference modulo 2**32, so ticks
    from interleaved outputs (an IMU sample, then a ToF reading stamped a little earlier) may step back
    slightly; the price is that a silence longer than half a wrap (≈33.5 s) is ambiguous. Feed ticks
    in arrival order, all kinds through the same instance: every kind then shares one time origin.
    """

    def __init__(self) -> None:
        self._last_raw: int | None = None
        self._last_total = 0

    def update(self, ticks: NDArray[np.integer]) -> NDArray[np.float64]:
        """Return (n,) device time in seconds for ``ticks`` (n,) in arrival order."""
        raw = np.asarray(ticks, dtype=np.int64)
        if raw.size == 0:
            return np.empty(0, dtype=np.float64)
        first = int(raw[0])
        if self._last_raw is None:
            self._last_raw = self._last_total = first
        # signed steps modulo 2**32 (differences taken in int32, which wrap), summed on from the last total
        total = np.empty(raw.size, dtype=np.int64)
        total[0] = self._last_total + (first - self._last_raw + TICK_WRAP // 2) % TICK_WRAP - TICK_WRAP // 2
        np.subtract(raw[1:], raw[:-1], out=total[1:], dtype=np.int32)
        np.add.accumulate(total, out=total)
        self._last_raw = int(raw[-1])
        self._last_total = int(total[-1])
        return total / TICK_HZ
