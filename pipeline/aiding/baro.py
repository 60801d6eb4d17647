"""Barometer readings and pressure altitude: decoded, shown, and not used in estimation.

Pressure altitude (ISA troposphere, ICAO Doc 7488): h = 44330.77 m · (1 − (p / p_ref)^0.190263),
here relative to the first valid reading of the session (p_ref), so it shows height changes.

The filter does not use it; why (next to the ToF aiding of ``footnav.pipeline.aiding.tof``): the
documentation's design page "ToF aiding".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class PressureBatch:
    """Barometer readings: t_s (m,) device time, s; pressure_pa (m,) (NaN when invalid)."""

    t_s: F64
    pressure_pa: F64

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True, slots=True)
class PressureAltitude:
    """Pressure altitude relative to the session's first valid reading: t_s (m,), altitude_m (m,)."""

    t_s: F64
    altitude_m: F64

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


class PressureAltimeter:
    """Pressure altitude of a stream of barometer readings (module docstring)."""

    def __init__(self) -> None:
        self.p_ref_pa = math.nan

    def update(self, readings: PressureBatch) -> PressureAltitude:
        p = np.asarray(readings.pressure_pa, dtype=np.float64)
        if not math.isfinite(self.p_ref_pa):
            ok = np.flatnonzero(np.isfinite(p) & (p > 0))
            if ok.size:
                self.p_ref_pa = float(p[ok[0]])
        with np.errstate(invalid="ignore"):
            alt = 44330.77 * (1.0 - (p / self.p_ref_pa) ** 0.190263)
        return PressureAltitude(np.asarray(readings.t_s, dtype=np.float64), alt)
