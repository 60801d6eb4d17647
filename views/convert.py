"""Pure conversions from :class:`footnav.pipeline.nav_types.NavBatch` to Rerun columns.

The numeric part (:func:`nav_arrays`) is plain numpy and testable without Rerun; :func:`nav_columns`
wraps it into ``(entity_path, columns)`` pairs for ``RecordingStream.send_columns``, all sharing the
one ``imu_time`` index. Quaternions are scalar-first (``wxyz``) everywhere in footnav; Rerun's
``xyzw`` order is produced here and only here (:func:`quat_wxyz_to_xyzw`, :func:`rotmat_to_quat_xyzw`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr
from footnav.pipeline.aiding.tof_measurement import USED as TOF_USED
from footnav.pipeline.nav_types import NavBatch, SmoothedSpan
from footnav.views.paths import TIMELINE, FootPaths
from numpy.typing import NDArray

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

DEFAULT_SIGMA_SCALE = 3.0
"""Covariance ellipsoids are drawn at this many standard deviations."""

STANCE_CLASS = 1
SWING_CLASS = 0
STANCE_STATE = "stance"
SWING_STATE = "swing"

SendColumns = tuple[str, rr.TimeColumn, rr.ComponentColumnList]
"""``(entity_path, index, columns)``: the arguments of one ``send_columns`` call."""


def quat_wxyz_to_xyzw(quat_wxyz: F64) -> F64:
    """Reorder scalar-first quaternions ``(..., 4)`` to Rerun's scalar-last ``(..., 4)``."""
    return np.ascontiguousarray(np.roll(np.asarray(quat_wxyz, dtype=np.float64), -1, axis=-1))


def rotmat_to_quat_xyzw(mat: F64) -> F64:
    """Rotation matrices ``(..., 3, 3)`` to unit quaternions ``(..., 4)`` in ``xyzw`` order.

    Shepperd's method: each quaternion is computed from its largest component, so rotations near
    180° (common for eigenvector bases, whose signs are arbitrary) come out as accurately as small ones.
    """
    mat = np.asarray(mat, dtype=np.float64)
    m = mat.reshape(-1, 3, 3)
    m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    trace = m00 + m11 + m22
    # 4·w², 4·x², 4·y², 4·z² (up to a common offset); pick the largest per matrix.
    cand = np.stack([trace, m00, m11, m22], axis=-1)
    choice = np.argmax(cand, axis=-1)
    r21, r12, r02, r20, r10, r01 = m[:, 2, 1], m[:, 1, 2], m[:, 0, 2], m[:, 2, 0], m[:, 1, 0], m[:, 0, 1]
    # (signs of m00, m11, m22 in 4·c²) and the other three components times 4·c, for c = w, x, y, z
    cases = (
        ((1, 1, 1), (r21 - r12, r02 - r20, r10 - r01), (0, 1, 2, 3)),  # w largest: [w | x, y, z]
        ((1, -1, -1), (r01 + r10, r02 + r20, r21 - r12), (1, 2, 3, 0)),  # x largest: [x | y, z, w]
        ((-1, 1, -1), (r01 + r10, r12 + r21, r02 - r20), (2, 1, 3, 0)),  # y largest: [y | x, z, w]
        ((-1, -1, 1), (r02 + r20, r12 + r21, r10 - r01), (3, 1, 2, 0)),  # z largest: [z | x, y, w]
    )
    w_x_y_z = np.empty((m.shape[0], 4))  # scalar-first scratch, reordered to xyzw at the end
    for k, ((a, b, c), others, slots) in enumerate(cases):
        sel = choice == k
        s = 2.0 * np.sqrt(np.maximum(1.0 + a * m00[sel] + b * m11[sel] + c * m22[sel], 1e-300))  # 4·|c|
        w_x_y_z[sel, slots[0]] = s / 4.0
        for slot, val in zip(slots[1:], others, strict=True):
            w_x_y_z[sel, slot] = val[sel] / s
    out = np.roll(w_x_y_z, -1, axis=-1)
    out /= np.linalg.norm(out, axis=-1, keepdims=True)
    return out.reshape(*mat.shape[:-2], 4)


def cov_ellipsoids(cov: F64, *, sigma_scale: float = DEFAULT_SIGMA_SCALE) -> tuple[F64, F64]:
    """Ellipsoid half-sizes and orientations of 3×3 covariances.

    Parameters
    ----------
    cov
        (n, 3, 3) covariance matrices (symmetrised here; non-finite ones become zero-size).
    sigma_scale
        half-sizes are ``sigma_scale * sqrt(eigenvalue)``.

    Returns
    -------
    tuple[F64, F64]
        half_sizes (n, 3) along the ellipsoid's own axes, and quat_xyzw (n, 4) rotating those axes
        into the covariance's frame, so that ``R diag(h²) Rᵀ = sigma_scale² · cov``.
    """
    p = np.asarray(cov, dtype=np.float64)
    p = 0.5 * (p + np.swapaxes(p, -1, -2))
    bad = ~np.isfinite(p).all(axis=(-1, -2))
    if bad.any():
        p = p.copy()
        p[bad] = 0.0
    evals, evecs = np.linalg.eigh(p)
    # eigh gives an orthonormal basis that may be a reflection; make it a rotation.
    flip = np.linalg.det(evecs) < 0
    evecs[flip, :, 2] *= -1.0
    half_sizes = sigma_scale * np.sqrt(np.clip(evals, 0.0, None))
    return half_sizes, rotmat_to_quat_xyzw(evecs)


def pos_sigmas(cov: F64) -> F64:
    """Standard deviations ``[σx, σy, σz, sqrt(trace)]`` (n, 4), m, from (n, 3, 3) covariances."""
    diag = np.clip(np.diagonal(np.asarray(cov, dtype=np.float64), axis1=-2, axis2=-1), 0.0, None)
    return np.concatenate([np.sqrt(diag), np.sqrt(diag.sum(axis=-1, keepdims=True))], axis=-1)


@dataclass(frozen=True, slots=True)
class NavArrays:
    """Column arrays for one batch of n samples, in the dtypes and orders Rerun takes.

    Attributes
    ----------
    t_s
        (n,) device time, s.
    pos
        (n, 3) float32 IMU position, m (track points, pose translation, ellipsoid centres).
    class_ids
        (n,) uint16, 1 = stance, 0 = swing.
    quat_xyzw
        (n, 4) float32 attitude body to navigation.
    pos_cov
        (n, 3, 3) position covariance, m² (ellipsoids: :meth:`ellipsoids`, for the rows shown).
    sigma_scale
        k of the k-sigma ellipsoids.
    stance
        (n,) float64 0.0 / 1.0.
    clearance
        (n,) float64, m.
    pos_sigma
        (n, 4) float64 ``[σx, σy, σz, sqrt(trace)]``, m.
    detector
        (n, 2) float64 ``[statistic, threshold]``.
    speed
        (n,) float64 horizontal speed, m/s.
    heading
        (n,) float64 heading, degrees in (−180, 180].
    """

    t_s: F64
    pos: F32
    class_ids: NDArray[np.uint16]
    quat_xyzw: F32
    pos_cov: F64
    sigma_scale: float
    stance: F64
    clearance: F64
    pos_sigma: F64
    detector: F64
    speed: F64
    heading: F64

    def ellipsoids(self, rows: slice = slice(None)) -> tuple[F32, F32]:
        """k-sigma ellipsoid half-sizes (m, 3) and orientations ``xyzw`` (m, 4), float32, of ``rows``
        (an eigen-decomposition each: only for the rows that are drawn)."""
        half_sizes, quat = cov_ellipsoids(self.pos_cov[rows], sigma_scale=self.sigma_scale)
        return half_sizes.astype(np.float32), quat.astype(np.float32)


def nav_arrays(
    nav: NavBatch, *, sigma_scale: float = DEFAULT_SIGMA_SCALE, heading_before_deg: float | None = None
) -> NavArrays:
    """Convert a NavBatch of n samples to :class:`NavArrays` (pure numpy): the detector as log10 of
    its statistic and threshold (they span five decades), the heading continuous from
    ``heading_before_deg`` (the previous batch's last) on."""
    n = len(nav)
    stance = np.asarray(nav.stance, dtype=bool)
    return NavArrays(
        t_s=np.asarray(nav.t_s, dtype=np.float64),
        pos=np.asarray(nav.pos_n_m, dtype=np.float32),
        class_ids=np.where(stance, STANCE_CLASS, SWING_CLASS).astype(np.uint16),
        quat_xyzw=quat_wxyz_to_xyzw(nav.quat_nb_wxyz).astype(np.float32),
        pos_cov=np.asarray(nav.pos_cov_n_m2, dtype=np.float64),
        sigma_scale=sigma_scale,
        stance=stance.astype(np.float64),
        clearance=np.asarray(nav.clearance_m, dtype=np.float64),
        pos_sigma=pos_sigmas(nav.pos_cov_n_m2),
        detector=log10_or_nan(
            np.stack(
                [
                    np.asarray(nav.detector_stat, dtype=np.float64),
                    np.broadcast_to(np.asarray(nav.detector_threshold, dtype=np.float64), (n,)),
                ],
                axis=-1,
            )
        ),
        speed=np.hypot(nav.vel_n_mps[:, 0], nav.vel_n_mps[:, 1]).astype(np.float64),
        heading=continuous_deg(heading_deg(nav.quat_nb_wxyz), heading_before_deg),
    )


def log10_or_nan(values: F64) -> F64:
    """log10 of the values, NaN where they are not positive."""
    v = np.asarray(values, dtype=np.float64)
    out = np.full(v.shape, np.nan)
    np.log10(v, out=out, where=v > 0)
    return out


def continuous_deg(angle_deg: F64, before_deg: float | None) -> F64:
    """Angles (n,) in degrees unwrapped into a continuous turn, continuing from ``before_deg``."""
    a = np.asarray(angle_deg, dtype=np.float64)
    if before_deg is None or not np.isfinite(before_deg):
        return np.unwrap(a, period=360.0)
    return np.unwrap(np.concatenate([[before_deg], a]), period=360.0)[1:]


def heading_deg(quat_nb_wxyz: F64) -> F64:
    """Heading (n,) in degrees, (−180, 180]: the yaw of the body x axis in the navigation frame,
    counter-clockwise from the navigation x axis (the start direction), from (n, 4) ``wxyz``."""
    q = np.asarray(quat_nb_wxyz, dtype=np.float64)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.degrees(np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


STEP_ELLIPSE_HALF_THICKNESS_M = 0.0005
"""Step ellipses are flat discs this thick (half), drawn on the floor under the step marker."""


def horizontal_block(cov: F64) -> F64:
    """(n, 2, 2) horizontal blocks of (n, ≥2, ≥2) covariances, symmetrised; zero where not finite."""
    p = np.asarray(cov, dtype=np.float64)[:, :2, :2]
    p = 0.5 * (p + np.swapaxes(p, -1, -2))
    finite: NDArray[np.bool_] = np.asarray(np.isfinite(p).all(axis=(-1, -2)))
    return np.where(finite[:, None, None], p, 0.0)


def floor_ellipses(cov: F64, *, sigma_scale: float = DEFAULT_SIGMA_SCALE) -> tuple[F64, F64]:
    """Flat ellipses of the horizontal 2×2 block of (n, 3, 3) position covariances.

    Returns
    -------
    tuple[F64, F64]
        half_sizes (n, 3): ``sigma_scale·sqrt(eigenvalue)`` along the ellipse axes and a thin z,
        and quat_xyzw (n, 4): the rotation about z taking the x axis to the major axis.
    """
    evals, evecs = np.linalg.eigh(horizontal_block(cov))  # ascending: column 1 is the major axis
    angle = np.arctan2(evecs[:, 1, 1], evecs[:, 0, 1])
    half = np.empty((evals.shape[0], 3))
    half[:, 0] = sigma_scale * np.sqrt(np.clip(evals[:, 1], 0.0, None))
    half[:, 1] = sigma_scale * np.sqrt(np.clip(evals[:, 0], 0.0, None))
    half[:, 2] = STEP_ELLIPSE_HALF_THICKNESS_M
    quat = np.zeros((evals.shape[0], 4))
    quat[:, 2] = np.sin(angle / 2.0)
    quat[:, 3] = np.cos(angle / 2.0)
    return half, quat


def stance_transitions(stance: NDArray[np.bool_], previous: bool | None) -> NDArray[np.intp]:
    """Indices (k,) where the stance flag differs from the sample before (or from ``previous``)."""
    s = np.asarray(stance, dtype=bool)
    if s.size == 0:
        return np.zeros(0, dtype=np.intp)
    change = np.empty(s.shape, dtype=bool)
    change[0] = previous is None or bool(s[0]) != previous
    change[1:] = s[1:] != s[:-1]
    return np.flatnonzero(change)


def time_column(t_s: F64) -> rr.TimeColumn:
    """The ``imu_time`` index for ``send_columns`` (duration, seconds)."""
    return rr.TimeColumn(TIMELINE, duration=np.asarray(t_s, dtype=np.float64))


def nav_columns(
    arrays: NavArrays,
    paths: FootPaths,
    *,
    ellipsoid_every: int = 1,
    first_index: int = 0,
    series_every: int = 1,
) -> list[SendColumns]:
    """``(entity, index, columns)`` triples for ``send_columns``, one per displayed entity.

    Every sample is logged for track, pose, stance, clearance, sigma and detector. The ellipsoid is
    logged for samples whose running index (``first_index`` + row) is a multiple of
    ``ellipsoid_every`` (1 = every sample, 0 = never), so decimation does not depend on batch borders;
    speed and heading likewise every ``series_every``-th sample.
    """
    index = time_column(arrays.t_s)
    out: list[SendColumns] = [
        (paths.track, index, rr.Points3D.columns(positions=arrays.pos, class_ids=arrays.class_ids)),
        (paths.pose, index, rr.Transform3D.columns(translation=arrays.pos, quaternion=arrays.quat_xyzw)),
        (paths.stance, index, rr.Scalars.columns(scalars=arrays.stance)),
        (paths.clearance, index, rr.Scalars.columns(scalars=arrays.clearance)),
        (paths.pos_sigma, index, rr.Scalars.columns(scalars=arrays.pos_sigma)),
        (paths.detector, index, rr.Scalars.columns(scalars=arrays.detector)),
    ]
    if series_every >= 1:
        sl_s = slice((-first_index) % series_every, None, series_every)
        if arrays.t_s[sl_s].size:
            s_index = index if series_every == 1 else time_column(arrays.t_s[sl_s])
            out.append((paths.speed, s_index, rr.Scalars.columns(scalars=arrays.speed[sl_s])))
            out.append((paths.heading, s_index, rr.Scalars.columns(scalars=arrays.heading[sl_s])))
    if ellipsoid_every < 1:
        return out
    sl = slice((-first_index) % ellipsoid_every, None, ellipsoid_every)
    t_cov = arrays.t_s[sl]
    if t_cov.size:
        cov_index = index if ellipsoid_every == 1 else time_column(t_cov)
        half_sizes, quat = arrays.ellipsoids(sl)
        cov_cols = rr.Ellipsoids3D.columns(centers=arrays.pos[sl], half_sizes=half_sizes, quaternions=quat)
        out.append((paths.cov, cov_index, cov_cols))
    return out


FLOOR_HIT_ON_LEVEL_RGB = (150, 150, 150)
"""Colour of a floor hit on a floor level (a tread or floor the foot has stood on)."""
FLOOR_HIT_OTHER_RGB = (230, 160, 40)
"""Colour of a floor hit elsewhere (a surface seen only in swing, a step edge's far side, a reflection)."""


def tof_columns(nav: NavBatch, paths: FootPaths, totals: NDArray[np.int64]) -> list[SendColumns]:
    """ToF, stride and barometer columns of one batch (empty when it has none).

    Each reading's floor hit (the 3D floor map); each sensor's measured height per valid reading;
    per-stride ``[min, max]`` clearance; the cumulative ``[used, gated, invalid status]`` reading
    counts (``totals`` (3,) is carried between batches and updated in place); pressure altitude.
    """
    out: list[SendColumns] = []
    r = nav.ranges
    if r is not None and len(r):
        hit = np.isfinite(r.hit_point_n_m[:, 0])
        if hit.any():
            colors = np.where(r.hit_on_level[hit, None], FLOOR_HIT_ON_LEVEL_RGB, FLOOR_HIT_OTHER_RGB).astype(np.uint8)
            out.append(
                (
                    paths.floor_hits,
                    time_column(r.t_s[hit]),
                    rr.Points3D.columns(positions=r.hit_point_n_m[hit], colors=colors),
                )
            )
        valid = np.isfinite(r.height_m)
        for k in np.unique(r.sensor[valid]).tolist():
            sel = valid & (r.sensor == k)
            out.append((paths.tof_height(int(k)), time_column(r.t_s[sel]), rr.Scalars.columns(scalars=r.height_m[sel])))
        used = r.code == TOF_USED
        invalid = r.status != 0
        gated = ~used & ~invalid
        counts = np.column_stack([used, gated, invalid]).astype(np.int64)
        cum = np.cumsum(counts, axis=0) + totals
        totals[:] = cum[-1]
        out.append((paths.tof_readings, time_column(r.t_s), rr.Scalars.columns(scalars=cum.astype(np.float64))))
    st = nav.strides
    if st is not None and len(st):
        out.append(
            (
                paths.stride_clearance,
                time_column(st.t_s),
                rr.Scalars.columns(scalars=np.column_stack([st.min_m, st.max_m])),
            )
        )
    alt = nav.altitude
    if alt is not None and len(alt):
        out.append((paths.altitude, time_column(alt.t_s), rr.Scalars.columns(scalars=alt.altitude_m)))
    return out


def smoothed_columns(span: SmoothedSpan, paths: FootPaths, *, every: int = 1) -> list[SendColumns]:
    """The step-smoothed track and its clearance (``footnav.pipeline.smoothing.stepwise``) at the samples' own
    times, of the samples whose index (``span.first_sample`` + row) is a multiple of ``every`` (so
    decimation does not depend on where steps end); empty when there are none."""
    sl = slice((-span.first_sample) % every, None, every)
    t_s = span.t_s[sl]
    if not len(t_s):
        return []
    pos = np.asarray(span.pos_n_m[sl], dtype=np.float32)
    return [
        (paths.smoothed, time_column(t_s), rr.Points3D.columns(positions=pos)),
        *series_columns(paths.smoothed_clearance, t_s, span.clearance_m[sl]),
    ]


def series_columns(path: str, t_s: F64, values: F64) -> list[SendColumns]:
    """One scalar series ``values`` (n,) at ``t_s`` (n,) on ``path`` (empty when n = 0)."""
    if not len(t_s):
        return []
    return [(path, time_column(t_s), rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)))]


def gait_columns(t_s: F64, stance: NDArray[np.bool_], paths: FootPaths, *, previous: bool | None) -> SendColumns | None:
    """StateChange column for the stance/swing lane, only at transitions (None when there are none)."""
    idx = stance_transitions(stance, previous)
    if idx.size == 0:
        return None
    states = np.where(np.asarray(stance, dtype=bool)[idx], STANCE_STATE, SWING_STATE).tolist()
    return paths.gait, time_column(np.asarray(t_s)[idx]), rr.StateChange.columns(state=states)


def step_columns(
    arrays: NavArrays, cov: F64, onsets: NDArray[np.intp], paths: FootPaths, *, sigma_scale: float
) -> list[SendColumns]:
    """Step markers and their floor ellipses at the given sample indices (empty list if none)."""
    if onsets.size == 0:
        return []
    index = time_column(arrays.t_s[onsets])
    pos = arrays.pos[onsets]
    half, quat = floor_ellipses(np.asarray(cov)[onsets], sigma_scale=sigma_scale)
    return [
        (paths.steps, index, rr.Points3D.columns(positions=pos)),
        (
            paths.step_cov,
            index,
            rr.Ellipsoids3D.columns(
                centers=pos, half_sizes=half.astype(np.float32), quaternions=quat.astype(np.float32)
            ),
        ),
    ]


def horizontal_error_m(t_s: F64, pos_n_m: F64, truth_t_s: F64, truth_pos_n_m: F64) -> F64:
    """(n,) horizontal distance of the (n, 3) estimates at ``t_s`` (n,) from the ground truth, m,
    linearly interpolated at those times; NaN outside the truth's time span."""
    tt = np.asarray(truth_t_s, dtype=np.float64)
    if tt.size < 2:
        return np.full(np.shape(t_s), np.nan)
    gx = np.interp(t_s, tt, truth_pos_n_m[:, 0], left=np.nan, right=np.nan)
    gy = np.interp(t_s, tt, truth_pos_n_m[:, 1], left=np.nan, right=np.nan)
    return np.hypot(np.asarray(pos_n_m)[:, 0] - gx, np.asarray(pos_n_m)[:, 1] - gy)
