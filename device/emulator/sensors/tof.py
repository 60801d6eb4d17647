"""Emulated time-of-flight range sensors on the shoe: VL53L0X-like units ranging the floor.

Each sensor is mounted at a lever arm ``lever_b_m`` from the IMU and looks along the unit vector
``dir_b`` (body axes: x toe, y left, z up). At its measurement times the sensor's position and ray in
the navigation frame follow from the true foot pose, ``s = p + R l_b`` and ``d = R u_b``, and the
range is the first hit of the ray ``s + ρ d`` with the floor surface (:mod:`.floors`): a tread (level
surface) or a riser (vertical face at a step edge). This is the geometry of the multi-sensor shoe of
Merat, Harvey and Mitsis (three VL53L0X sensors pointing at the floor; their eqs. 20-21 invert it).

Sensor behaviour modelled (after the VL53L0X datasheet, ST DS11555, in its default mode):

- one measurement every ``period_s`` (≈ 33 Hz, the 30 ms timing budget), the sensors staggered by a
  third of a period so the floor is ranged at about 100 Hz in all;
- ``sigma_m`` (1 cm) Gaussian range noise; the wire quantises to 1 mm;
- status :data:`~footnav.device.protocol.extensions.TOF_NO_TARGET` when nothing is hit within ``max_range_m`` (2 m) or
  the ray points up;
- status :data:`~footnav.device.protocol.extensions.TOF_WEAK_SIGNAL` when the ray meets the surface further than
  ``max_incidence_rad`` from its normal (a tilted foot, a riser hit at grazing angle): too little light
  comes back. The VL53L0X has no published incidence limit; 40° is this model's assumption;
- status :data:`~footnav.device.protocol.extensions.TOF_TIMEOUT` at random with probability ``timeout_rate``;
- optional spurious ranges with a valid status (``spurious_rate``): a glossy floor seen specularly
  returns a longer, mirrored path, modelled as the true range plus a uniform 0.05-0.5 m. They are what
  the host's innovation gate must catch.

All randomness comes from one seeded generator, so a script is reproducible.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
from footnav.device.emulator.motion.floors import Floor
from footnav.device.emulator.scripts import TofScript
from footnav.device.protocol import extensions
from footnav.pipeline.aiding.tof_types import DEFAULT_DIR_B, DEFAULT_LEVER_B_M
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class TofMount:
    """One sensor's mounting: ``lever_b_m`` (3,) from the IMU, ``dir_b`` (3,) unit viewing direction."""

    lever_b_m: tuple[float, float, float]
    dir_b: tuple[float, float, float]


DEFAULT_MOUNTS: tuple[TofMount, ...] = tuple(
    TofMount(lever, direction) for lever, direction in zip(DEFAULT_LEVER_B_M, DEFAULT_DIR_B, strict=True)
)
"""Toe, mid-foot and heel sensors, 3-4 cm above the IMU's reference point (which rests on the floor
in the gait model), looking roughly down: the mounting the navigator assumes by default
(``footnav.pipeline.aiding.tof_types.DEFAULT_LEVER_B_M``, ``DEFAULT_DIR_B``)."""


@dataclass(frozen=True, slots=True)
class TofSensorModel:
    """Sensor settings (see the module docstring)."""

    mounts: tuple[TofMount, ...] = DEFAULT_MOUNTS
    period_s: float = 0.030
    sigma_m: float = 0.01
    max_range_m: float = 2.0
    max_incidence_rad: float = math.radians(40.0)
    timeout_rate: float = 0.005
    spurious_rate: float = 0.0
    seed: int = 0


def ray_cast(origin_n_m: F64, dir_n: F64, floor: Floor, max_range_m: float) -> tuple[F64, F64]:
    """First hit of rays with a floor of level treads and vertical risers.

    Parameters
    ----------
    origin_n_m
        (m, 3) ray origins.
    dir_n
        (m, 3) unit directions.
    floor
        the floor.
    max_range_m
        rays are followed this far.

    Returns
    -------
    range_m : F64
        (m,) (NaN: no hit within range, or the origin is under the floor).
    cos_incidence : F64
        (m,), the cosine between the reversed ray and the normal of the surface hit.
    """
    m = origin_n_m.shape[0]
    out_range = np.full(m, np.nan)
    out_cos = np.full(m, np.nan)
    edges = floor.edges_x_m
    for i in range(m):
        sx, sz = float(origin_n_m[i, 0]), float(origin_n_m[i, 2])
        dx, dz = float(dir_n[i, 0]), float(dir_n[i, 2])
        # breakpoints where the ray's x crosses an edge, within (0, max_range)
        ts = [0.0]
        if edges.size and abs(dx) > 1e-12:
            te = (edges - sx) / dx
            ts.extend(sorted(float(t) for t in te if 0.0 < t < max_range_m))
        ts.append(max_range_m)
        for a, b in itertools.pairwise(ts):
            level = float(floor.height_m(np.array([sx + 0.5 * (a + b) * dx]))[0])
            za = sz + a * dz
            if za <= level:
                if a > 0.0:  # the ray meets the riser at this edge
                    out_range[i] = a
                    out_cos[i] = abs(dx)
                break
            if dz < 0.0:
                t_hit = (sz - level) / -dz
                if t_hit <= b:
                    out_range[i] = t_hit
                    out_cos[i] = -dz
                    break
    return out_range, out_cos


def _pose_at(t_s: F64, truth_t_s: F64, pos_n_m: F64, quat_nb_wxyz: F64) -> tuple[F64, F64]:
    """Position (m, 3) and rotation matrices (m, 3, 3) at ``t_s``: linear and normalised-linear
    interpolation between the 1 kHz truth samples."""
    pos = np.column_stack([np.interp(t_s, truth_t_s, pos_n_m[:, k]) for k in range(3)])
    q = np.column_stack([np.interp(t_s, truth_t_s, quat_nb_wxyz[:, k]) for k in range(4)])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    mat = np.empty((t_s.size, 3, 3))
    mat[:, 0, 0] = w * w + x * x - y * y - z * z
    mat[:, 0, 1] = 2 * (x * y - w * z)
    mat[:, 0, 2] = 2 * (x * z + w * y)
    mat[:, 1, 0] = 2 * (x * y + w * z)
    mat[:, 1, 1] = w * w - x * x + y * y - z * z
    mat[:, 1, 2] = 2 * (y * z - w * x)
    mat[:, 2, 0] = 2 * (x * z - w * y)
    mat[:, 2, 1] = 2 * (y * z + w * x)
    mat[:, 2, 2] = w * w - x * x - y * y + z * z
    return pos, mat


def tof_readings(
    truth_t_s: F64,
    pos_n_m: F64,
    quat_nb_wxyz: F64,
    floor: Floor,
    model: TofSensorModel | None = None,
) -> TofScript:
    """The readings of the shoe's ToF sensors along a true trajectory.

    Parameters
    ----------
    truth_t_s
        (n,) truth sample times, s.
    pos_n_m
        (n, 3) true IMU position.
    quat_nb_wxyz
        (n, 4) true attitude, body to navigation.
    floor
        the floor walked on (:func:`.floors.floor_of`).
    model
        sensor settings (default :class:`TofSensorModel`).

    Returns
    -------
    TofScript
        A :class:`~.scripts.TofScript` in time order: t_s (m,), sensor (m,), range_m (m,) (NaN where the status is not
        valid), status (m,).
    """
    model = model or TofSensorModel()
    truth_t_s = np.asarray(truth_t_s, dtype=np.float64)
    k = len(model.mounts)
    times, sensors = [], []
    for j in range(k):
        tj = np.arange(truth_t_s[0] + (j + 1) * model.period_s / k, truth_t_s[-1], model.period_s)
        times.append(tj)
        sensors.append(np.full(tj.size, j, dtype=np.int64))
    t_all = np.concatenate(times)
    sensor = np.concatenate(sensors)
    order = np.argsort(t_all, kind="stable")
    t_all, sensor = t_all[order], sensor[order]
    pos, mat = _pose_at(t_all, truth_t_s, pos_n_m, quat_nb_wxyz)
    lever = np.asarray([mt.lever_b_m for mt in model.mounts])[sensor]
    dirs = np.asarray([mt.dir_b for mt in model.mounts])[sensor]
    origin = pos + np.einsum("mij,mj->mi", mat, lever)
    dir_n = np.einsum("mij,mj->mi", mat, dirs)
    true_range, cos_inc = ray_cast(origin, dir_n, floor, model.max_range_m)

    rng = np.random.default_rng(model.seed)
    status = np.full(t_all.size, extensions.TOF_VALID, dtype=np.uint8)
    status[~np.isfinite(true_range)] = extensions.TOF_NO_TARGET
    weak = np.isfinite(cos_inc) & (cos_inc < math.cos(model.max_incidence_rad))
    status[weak] = extensions.TOF_WEAK_SIGNAL
    status[rng.random(t_all.size) < model.timeout_rate] = extensions.TOF_TIMEOUT
    measured = true_range + model.sigma_m * rng.standard_normal(t_all.size)
    spurious = (rng.random(t_all.size) < model.spurious_rate) & (status == extensions.TOF_VALID)
    measured[spurious] = true_range[spurious] + rng.uniform(0.05, 0.5, int(spurious.sum()))
    measured = np.clip(measured, 0.0, model.max_range_m)
    measured[status != extensions.TOF_VALID] = np.nan
    return TofScript(t_all, sensor, measured, status)
