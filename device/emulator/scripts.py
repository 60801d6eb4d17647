"""What an emulated unit has to say: per-mode data containers and their derivation from gait truth.

Every container is plain arrays in footnav's frame and SI units; the emulator's firmware
(:mod:`.firmware`) encodes them into the unit's packets (and into OpenShoe's z-down frame where the
wire uses it). Helpers derive:

- :func:`steps_from_truth`: the stepwise-dead-reckoning steps a unit would report, from the true
  position and heading at its filter resets (stance phases). Emission follows the firmware logic of
  protocol-openshoe.md 5.1: a reset when a stance lasts ``pending_s`` or ends, but not sooner than
  ``min_between_s`` after the previous one; standing still therefore gives a ≈zero step about every
  ``min_between_s + pending_s``. Each step is the true displacement since the previous reset, in the
  heading frame of that reset, and the true heading change, so the steps sum to the truth;
- :func:`steps_from_footholds`: the same from a footholds table (one step per stride);
- :func:`baro_from_height`: barometric pressure from height (ISA troposphere).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

RESET_PENDING_S: Final = 0.25
"""``max_time_reset_pending`` of the MIMU-era firmware (protocol-openshoe.md 5.1)."""
RESET_MIN_BETWEEN_S: Final = 0.75
"""``min_time_between_resets`` of the MIMU-era firmware."""
SEA_LEVEL_PA: Final = 101_325.0


@dataclass(frozen=True, slots=True)
class InsTruth:
    """INS states at the base sample times: pos (n, 3) m, vel (n, 3) m/s, quat_nb_wxyz (n, 4), cov (n, 9, 9).

    Footnav frame (z up); the emulator sends them in OpenShoe's z-down frame.
    """

    pos_n_m: F64
    vel_n_mps: F64
    quat_nb_wxyz: F64
    cov_9x9: F64 | None = None


@dataclass(frozen=True, slots=True)
class StepScript:
    """Stepwise-dead-reckoning packets to send, at device times ``t_s`` (m,).

    Attributes
    ----------
    t_s
        (m,) emission (filter reset) times, s, increasing.
    dx_m
        (m, 3) displacement since the previous reset in that reset's heading frame, z up.
    dheading_rad
        (m,) heading change, rad.
    cov_4x4
        (m, 4, 4) covariance of (dx, dy, dz, dψ).
    pos_n_m
        (m, 3) true position at each reset relative to the start, in the start's heading frame (the unit's frame after
        alignment): the track a host should rebuild.
    heading_rad
        (m,) true heading at each reset relative to the start heading.
    """

    t_s: F64
    dx_m: F64
    dheading_rad: F64
    cov_4x4: F64
    pos_n_m: F64
    heading_rad: F64

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


@dataclass(frozen=True, slots=True)
class TofScript:
    """ToF readings: t_s (m,), sensor (m,), range_m (m,) (NaN = none), status (m,).

    Made from a true trajectory by :func:`footnav.device.emulator.sensors.tof.tof_readings`.
    """

    t_s: F64
    sensor: NDArray[np.int64]
    range_m: F64
    status: NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class BaroScript:
    """Barometer readings: t_s (m,), pressure_pa (m,), temperature_c (m,)."""

    t_s: F64
    pressure_pa: F64
    temperature_c: F64


def step_cov(dx_m: F64) -> F64:
    """A plausible per-step covariance: 1 cm + 1 % horizontal, 5 mm vertical, 0.2° heading (σ)."""
    length = np.linalg.norm(np.asarray(dx_m)[:, :2], axis=1)
    s_xy = 0.01 + 0.01 * length
    cov = np.zeros((len(length), 4, 4))
    cov[:, 0, 0] = cov[:, 1, 1] = s_xy**2
    cov[:, 0, 1] = cov[:, 1, 0] = 0.1 * s_xy**2
    cov[:, 2, 2] = 0.005**2
    cov[:, 3, 3] = np.radians(0.2) ** 2
    return cov


def _rotate_z(vec: F64, angle_rad: float) -> F64:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.column_stack([c * vec[:, 0] - s * vec[:, 1], s * vec[:, 0] + c * vec[:, 1], vec[:, 2]])


def _steps(t_s: F64, pos: F64, yaw: F64) -> StepScript:
    """Steps between consecutive reset poses; row 0 of the inputs is the start (no packet)."""
    d_n = np.diff(pos, axis=0)
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    dx = np.column_stack([c * d_n[:, 0] + s * d_n[:, 1], -s * d_n[:, 0] + c * d_n[:, 1], d_n[:, 2]])
    return StepScript(
        t_s=np.asarray(t_s[1:], dtype=np.float64),
        dx_m=dx,
        dheading_rad=np.diff(yaw),
        cov_4x4=step_cov(dx),
        pos_n_m=_rotate_z(pos[1:] - pos[0], -float(yaw[0])),
        heading_rad=yaw[1:] - yaw[0],
    )


def reset_indices(
    t_s: F64,
    stance: NDArray[np.bool_],
    *,
    pending_s: float = RESET_PENDING_S,
    min_between_s: float = RESET_MIN_BETWEEN_S,
) -> NDArray[np.int64]:
    """Sample indices of the filter resets (packet emissions) for a stance mask (n,)."""
    st = np.asarray(stance, dtype=bool)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], st.astype(np.int8), [0]])))
    out: list[int] = []
    last_t = float(t_s[0])
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # stance runs [a, b)
        t_a, t_end = float(t_s[a]), float(t_s[b - 1])
        cand = max(t_a + pending_s, last_t + min_between_s)
        while cand <= t_end:  # still standing: a reset every pending period after the spacing
            i = int(np.searchsorted(t_s, cand))
            out.append(i)
            last_t = float(t_s[i])
            cand = last_t + min_between_s + pending_s
        if b < len(st) and t_end - last_t >= min_between_s and (not out or out[-1] < b - 1):
            out.append(b - 1)  # the ZUPT ends: reset on the last still sample
            last_t = t_end
    return np.asarray(out, dtype=np.int64)


def steps_from_truth(t_s: F64, pos_n_m: F64, yaw_rad: F64, stance: NDArray[np.bool_], **reset_kw: float) -> StepScript:
    """The SWDR packets a unit would send for a true trajectory (see the module docstring).

    Parameters
    ----------
    t_s
        (n,) sample times, s.
    pos_n_m
        (n, 3) true position, footnav frame.
    yaw_rad
        (n,) true heading (continuous).
    stance
        (n,) True where the foot is still.
    reset_kw
        ``pending_s`` / ``min_between_s`` overrides.
    """
    idx = np.concatenate([[0], reset_indices(t_s, stance, **reset_kw)])
    return _steps(np.asarray(t_s)[idx], np.asarray(pos_n_m)[idx], np.asarray(yaw_rad)[idx])


def steps_from_footholds(xyz_yaw: F64, t_s: F64) -> StepScript:
    """One step per stride from (m + 1, 4) footholds ``(x, y, z, yaw)``, emitted at ``t_s`` (m + 1,).

    Row 0 is the start (no packet).
    """
    xyz_yaw = np.asarray(xyz_yaw, dtype=np.float64)
    return _steps(np.asarray(t_s, dtype=np.float64), xyz_yaw[:, :3], xyz_yaw[:, 3])


def yaw_from_quat_wxyz(quat_nb_wxyz: F64) -> F64:
    """Heading (ZYX yaw) of body-to-nav quaternions (n, 4), continuous."""
    w, x, y, z = np.asarray(quat_nb_wxyz, dtype=np.float64).T
    return np.unwrap(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def baro_from_height(
    t_s: F64,
    height_m: F64,
    *,
    rate_hz: float = 25.0,
    temperature_c: float = 21.0,
    base_height_m: float = 100.0,
) -> BaroScript:
    """ISA-troposphere pressure p = p0 (1 − 2.25577e-5 h)^5.25588 at ``rate_hz`` along ``height_m``."""
    t_s = np.asarray(t_s, dtype=np.float64)
    tb = np.arange(t_s[0], t_s[-1], 1.0 / rate_hz)
    h = np.interp(tb, t_s, height_m) + base_height_m
    pressure = SEA_LEVEL_PA * (1.0 - 2.25577e-5 * h) ** 5.25588
    return BaroScript(tb, pressure, np.full(tb.size, temperature_c))
