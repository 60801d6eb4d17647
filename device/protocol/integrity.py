"""Values no OpenShoe-family unit can send: what the 16-bit checksum misses and the unit cannot produce.

Two bit flips that cancel pass the additive checksum (about 0.5 % of the corrupted packets at a bit
error rate of 1e-3: ``benchmarks/integrity.py``). Their number and time stamp are checked against
the run (:mod:`footnav.device.protocol.sequence`); their values here, each record rejected whole:

- a value beyond what the sensor can measure: ±:data:`ACC_RANGE_MPS2` and ±:data:`GYR_RANGE_RADPS` per
  axis, the family's largest full scales (±18 g, ADIS16367; ±2000 °/s, MPU-6500) with room for the
  factory calibration's gains; anything not finite;
- a step from the last accepted sample that no foot makes: more than :data:`ACC_STEP_MPS2` or
  :data:`GYR_STEP_RADPS` on one axis per package number (at most three numbers' worth after a gap).
  The real recordings' largest steps between samples are 102 m/s² and 8.7 rad/s (PyShoe running
  trials at 200 Hz, where a sample spans five of a 1 kHz unit); ``tests/test_packet_integrity.py``
  keeps every sample of every recording in ``shared/data`` and of the emulated stairs. Two rejected
  samples in a row that agree with each other mean the reference was wrong: the second is accepted;
- INS states: a quaternion whose norm is not 1 (the firmware normalises it), a position beyond
  :data:`INS_POS_MAX_M` or a velocity beyond :data:`INS_VEL_MAX_MPS`;
- stepwise packets: a displacement beyond :data:`STEP_MAX_M`, a heading change beyond 2π, a
  covariance with a negative or non-finite diagonal.

What stays: flips in the low bits of a float's mantissa (a relative change below 2⁻⁸, within the
sensor's noise) and in a time stamp's low bits (under a quarter of a sample period). No receiver can
tell those from a packet the unit sent.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
from numpy.typing import NDArray

G0: Final = 9.80665
ACC_RANGE_MPS2: Final = 20.0 * G0
"""Largest |specific force| per axis an OpenShoe-family unit reports (±18 g full scale, calibrated)."""
GYR_RANGE_RADPS: Final = 2300.0 * math.pi / 180.0
"""Largest |angular rate| per axis (±2000 °/s full scale, calibrated)."""
ACC_STEP_MPS2: Final = 200.0
"""Largest change of specific force on one axis per package number (twice the real recordings' largest)."""
GYR_STEP_RADPS: Final = 40.0
"""Largest change of angular rate on one axis per package number (over four times the real recordings' largest)."""
MAX_STEP_SPAN: Final = 3
"""A gap loosens the step bounds by at most this many package numbers' worth."""
INS_POS_MAX_M: Final = 1e5
INS_VEL_MAX_MPS: Final = 50.0
QUAT_NORM_TOL: Final = 1e-3
STEP_MAX_M: Final = 5.0
_TILE_ROWS: Final = 1024
"""Rows of the bounds kept tiled for the common test (more when a longer run comes)."""


class ImuGuard:
    """Rejects IMU records beyond the sensor's range or a step away from the last accepted one.

    Parameters
    ----------
    acc_range, gyr_range
        per-axis range, m/s² and rad/s (None: no range check, e.g. int16 registers that cannot exceed it).
    """

    def __init__(self, acc_range: float | None = ACC_RANGE_MPS2, gyr_range: float | None = GYR_RANGE_RADPS) -> None:
        self._acc_range = math.inf if acc_range is None else acc_range
        self._gyr_range = math.inf if gyr_range is None else gyr_range
        self._bounds: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None  # per column: range, step
        self._last: tuple[int, NDArray[np.float64]] | None = None  # the last accepted record, [acc | gyr]
        self._tiled: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None  # _bounds, row after row
        self.rejected = 0
        """Records rejected so far."""

    def check(
        self, counter: NDArray[np.int64], acc: NDArray[np.floating], gyr: NDArray[np.floating]
    ) -> NDArray[np.bool_]:
        """Accept mask (n,) of the records at package numbers ``counter`` (n,), in order, with
        specific force ``acc`` (n, k·3) and angular rate ``gyr`` (n, k·3) (k IMUs side by side)."""
        n = len(counter)
        a = np.asarray(acc, dtype=np.float64).reshape(n, -1)
        x = np.concatenate((a, np.asarray(gyr, dtype=np.float64).reshape(n, -1)), axis=1)
        return self.check_rows(counter, x, a.shape[1])

    def check_rows(self, counter: NDArray[np.int64], x: NDArray[np.float64], acc_cols: int) -> NDArray[np.bool_]:
        """As :meth:`check`, with the records as the rows of ``x`` (n, 2·k·3) float64: their first
        ``acc_cols`` columns specific force, m/s², the others angular rate, rad/s."""
        n = len(counter)
        if self.accepts_all(counter, x, acc_cols):
            return np.ones(n, dtype=np.bool_)
        assert self._bounds is not None
        limit, step = self._bounds
        ok: NDArray[np.bool_] = np.asarray((np.abs(x) <= limit).all(axis=1), dtype=np.bool_)  # NaN fails
        prev_rejected: NDArray[np.float64] | None = None
        for i in np.flatnonzero(ok):
            c, xi = int(counter[i]), x[i]
            if self._last is None or self._near(xi - self._last[1], step, c - self._last[0]):
                self._last, prev_rejected = (c, xi), None
            elif prev_rejected is not None and self._near(xi - prev_rejected, step, 1):
                self._last, prev_rejected = (c, xi), None  # two that agree: the reference was wrong
            else:
                ok[i] = False
                prev_rejected = xi
        self.rejected += int(np.count_nonzero(~ok))
        return ok

    def accepts_all(self, counter: NDArray[np.int64], x: NDArray[np.float64], acc_cols: int) -> bool:
        """True, and the records taken as accepted, when a quick test shows that :meth:`check_rows` would
        accept every one (all in range, each within one number's step of the one before); else False, and
        nothing changed: :meth:`check_rows` decides. A few vectorised operations."""
        if self._bounds is None or self._bounds[0].shape[0] != x.shape[1]:
            acc = np.arange(x.shape[1]) < acc_cols
            self._bounds = (
                np.where(acc, self._acc_range, self._gyr_range),
                np.where(acc, ACC_STEP_MPS2, GYR_STEP_RADPS),
            )
            self._last = self._tiled = None
        if len(counter) and self._all_near(x):
            self._last = (int(counter[-1]), x[-1])
            return True
        return False

    def _all_near(self, x: NDArray[np.float64]) -> bool:
        """Every record in range and within one number's step of the one before (NaN fails every
        comparison)."""
        n, k = x.shape
        tiled = self._tiled
        if tiled is None or tiled[0].shape[0] < n or tiled[0].shape[1] != k:
            assert self._bounds is not None
            # the bounds repeated row by row: comparing two (n, k) blocks runs as one loop, not n loops of k
            rows = max(n, _TILE_ROWS)
            tiled = self._tiled = (np.tile(self._bounds[0], (rows, 1)), np.tile(self._bounds[1], (rows, 1)))
        limit, step = tiled[0][:n], tiled[1][:n]
        d = np.abs(x)
        size = d.size  # count_nonzero: a quicker all() for a few hundred values
        if np.count_nonzero(d <= limit) != size:
            return False
        if self._last is None:
            d[0] = 0.0
        else:
            np.subtract(x[0], self._last[1], out=d[0])
        np.subtract(x[1:], x[:-1], out=d[1:])
        return int(np.count_nonzero(np.abs(d, out=d) <= step)) == size

    @staticmethod
    def _near(d: NDArray[np.float64], step: NDArray[np.float64], span: int) -> bool:
        return bool((np.abs(d) <= step * min(max(span, 1), MAX_STEP_SPAN)).all())


def ins_plausible(
    pos: NDArray[np.floating] | None, vel: NDArray[np.floating] | None, quat: NDArray[np.floating] | None
) -> NDArray[np.bool_]:
    """Accept mask (n,) of INS states: (n, 3) position, m, (n, 3) velocity, m/s, (n, 4) quaternion (each
    may be None)."""
    n = next(len(x) for x in (pos, vel, quat) if x is not None) if any(x is not None for x in (pos, vel, quat)) else 0
    ok = np.ones(n, dtype=np.bool_)
    for x, limit in ((pos, INS_POS_MAX_M), (vel, INS_VEL_MAX_MPS)):
        if x is not None:
            ok &= (np.abs(np.asarray(x, dtype=np.float64)) <= limit).all(axis=1)  # NaN fails too
    if quat is not None:
        ok &= np.abs(np.linalg.norm(np.asarray(quat, dtype=np.float64), axis=1) - 1.0) <= QUAT_NORM_TOL
    return ok


def step_plausible(
    dx_m: NDArray[np.floating], dheading_rad: NDArray[np.floating], cov_4x4: NDArray[np.floating]
) -> NDArray[np.bool_]:
    """Accept mask (n,) of stepwise packets: (n, 3) displacement, (n,) heading change, (n, 4, 4) covariance."""
    diag = np.diagonal(np.asarray(cov_4x4, dtype=np.float64), axis1=1, axis2=2)
    return (
        (np.abs(np.asarray(dx_m, dtype=np.float64)) <= STEP_MAX_M).all(axis=1)
        & (np.abs(np.asarray(dheading_rad, dtype=np.float64)) <= 2.0 * math.pi)
        & np.isfinite(np.asarray(cov_4x4, dtype=np.float64)).all(axis=(1, 2))
        & (diag >= 0.0).all(axis=1)
    )
