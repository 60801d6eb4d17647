"""The floor under the courses of :mod:`.paths`: height as a function of horizontal position.

Flat courses (``line``, ``rectangle``, ``figure8``) walk on ``z = 0``. The ``stairs`` course climbs a
straight flight along +x from the start foothold, which stands half a tread before the first riser
(:func:`.paths.stairs`): riser k (k = 0 .. N−1) is at ``x = (k + ½) · tread``, so

    z(x, y) = riser · clip(⌊x / tread + ½⌋, 0, N)

for every y: the way down uses the other half of the same flight, the ground floor and the landing
are level (the landing's far end is beyond the turn walked on it). This is the geometry the gait
model's ``floor_z_m`` follows for the IMU (edges crossed as the foot passes them); a ToF ray cast
against it (:mod:`.tof_sensors`) hits the lower or the upper tread as the real one would.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from footnav.device.emulator.motion import paths
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class Floor:
    """A floor made of level treads along x: ``edges_x_m`` (k,) increasing, ``levels_z_m`` (k + 1,).

    ``levels_z_m[j]`` is the height between ``edges_x_m[j − 1]`` and ``edges_x_m[j]`` (level 0 before
    the first edge, the last level after the last). A flat floor has no edges and one level.
    """

    edges_x_m: F64
    levels_z_m: F64

    def height_m(self, x_m: F64, y_m: F64 | None = None) -> F64:
        """Floor height (n,) under the points (x, y) (n,); y does not matter for these floors."""
        idx = np.searchsorted(self.edges_x_m, np.asarray(x_m, dtype=np.float64), side="right")
        return np.asarray(self.levels_z_m[idx], dtype=np.float64)


def floor_of(path: str) -> Floor:
    """The floor of a course of :data:`.paths.PATHS`.

    Raises
    ------
    ValueError
        an unknown course.
    """
    if path not in paths.PATHS:
        raise ValueError(f"unknown path {path!r}; expected one of {sorted(paths.PATHS)}")
    if path != "stairs":
        return Floor(np.empty(0), np.zeros(1))
    k = np.arange(paths.STAIR_N_STEPS, dtype=np.float64)
    edges = (k + 0.5) * paths.STAIR_TREAD_M
    levels = np.arange(paths.STAIR_N_STEPS + 1, dtype=np.float64) * paths.STAIR_RISER_M
    return Floor(edges, levels)
