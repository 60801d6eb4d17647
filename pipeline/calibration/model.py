"""Field calibration of the IMU: the 15-parameter accelerometer model and gyroscope biases, from still faces.

Accelerometer model (per sample, body frame of the sensor, SI units)::

    y = K L u + (K_T u + b_T) ΔT + b + w,        ΔT = temp_c − t_ref_c

- ``u``: the true specific force (at rest ``|u| = g``), m/s²;
- ``K = diag(k)``: scale factors (3); ``K_T = diag(k_T)``: their temperature slopes, 1/°C (3);
- ``L``: lower-triangular with a unit diagonal, ``L[1,0] = l_yx, L[2,0] = l_zx, L[2,1] = l_zy``: misalignment and
  cross-axis coupling (3); the body frame is defined by the sensor's x axis and its xy plane (Tedaldi et al. 2014);
- ``b``: bias (3), m/s²; ``b_T``: its temperature slope (3), m/s²/°C; ``w``: noise.

On each still face only ``|u| = g`` is known, so each still window's mean is inverted,
``u_j = (K L + K_T ΔT_j)⁻¹ (y_j − b − b_T ΔT_j)``, and ``Σ_j (|u_j| − g)²`` is minimised over the 15 parameters
with scipy's trust-region-reflective least squares (``method="trf"``). Parameter uncertainties are
``σ̂² (JᵀJ)⁻¹`` at the solution (pseudo-inverse by SVD), ``σ̂² = Σ r² / (m − p)``. Gyroscope: at rest the rate is
zero (Earth rotation, ≤ 0.0042 °/s, is absorbed in the bias): ``y_g = ω + b_g + b_gT ΔT + w``, fitted by linear
least squares over the captures. ``t_ref_c`` is the mean temperature of the procedure; a stream without
temperature (the calibrated-IMU output 0x40) is corrected at ``t_ref_c``.

The fit raises a :class:`CalibrationError` saying what to redo instead of returning parameters it cannot
determine: too few distinct faces or faces that do not span 3D, motion or saturation within a face, a temperature
that barely changed (the 9-parameter model without temperature terms is fitted only if the caller allows it, and
the result says so). Why: the documentation's design page "Calibration".

References: Tedaldi, Pretto, Menegatti (2014), A robust and easy to implement method for IMU calibration without
external equipments, *IEEE ICRA*, 3042-3049; Merat, P., et al. (the 15-parameter model with K, L, B and K_T, B_T),
as used by the multi-sensor foot platform paper; Branch, Coleman, Li (1999), *SIAM J. Sci. Comput.* 21(1), 1-23
(the "trf" method of ``scipy.optimize.least_squares``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Final

import numpy as np
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.samples import ImuBatch
from numpy.typing import NDArray

F64 = NDArray[np.float64]

MODEL_VERSION: Final = 1
STANDARD_GRAVITY_MPS2: Final = 9.80665
ACC_LIMIT_MPS2: Final = 32767 / 2048.0 * STANDARD_GRAVITY_MPS2
"""Largest register value of a ±16 g accelerometer (MPU-6500 class as the firmware sets it), m/s²."""
GYR_LIMIT_RADPS: Final = math.radians(32767 / 16.4)
"""Largest register value of a ±2000 °/s gyroscope, rad/s."""
WINDOW_S: Final = 0.5
"""Still captures are averaged in windows of this length (each window is one residual)."""
MIN_FACES: Final = 12
"""Distinct faces needed for the 15-parameter model (the icosahedron has 20)."""
MIN_FACES_NO_TEMPERATURE: Final = 9
"""Distinct faces needed for the 9-parameter model (no temperature terms)."""
FACE_SEPARATION_DEG: Final = 20.0
"""Two captures whose gravity directions are closer than this are the same face (icosahedron faces are
41.8° apart)."""
MIN_TEMPERATURE_SPREAD_C: Final = 3.0
"""Below this spread of the window temperatures the temperature terms are unobservable."""
MOTION_ACC_STD_MPS2: Final = 0.15
"""A capture whose windows' mean acceleration varies more than this (per axis, 1σ) was not still."""
MOTION_GYR_MEAN_RADPS: Final = math.radians(3.0)
"""A capture whose angular rate departs from its mean by more than this (window means) was not still."""

TOLERANCE: Final = {
    "scale": 1e-3,
    "misalignment_rad": math.radians(0.05),
    "acc_bias_mps2": 2e-3 * STANDARD_GRAVITY_MPS2,
    "gyr_bias_radps": math.radians(0.01),
}
"""The issue's accuracy targets: a fit is *well determined* when 3σ of each is inside them."""

PARAM_NAMES: Final = (
    "k_x", "k_y", "k_z", "l_yx", "l_zx", "l_zy", "b_x", "b_y", "b_z",
    "kt_x", "kt_y", "kt_z", "bt_x", "bt_y", "bt_z",
)  # fmt: skip


class CalibrationError(FootnavError):
    """The calibration cannot be determined from these captures; the message says what to redo."""


class TooFewFacesError(CalibrationError):
    """Fewer distinct faces than the model needs, or faces that do not span 3D."""


class MotionError(CalibrationError):
    """The unit moved during a still capture."""


class SaturationError(CalibrationError):
    """A sensor hit its range during a still capture."""


class TemperatureUnobservableError(CalibrationError):
    """The temperature barely changed (or is unknown), so K_T and b_T cannot be determined."""


class IllDeterminedError(CalibrationError):
    """The fit ran but some parameters are not determined to the required accuracy."""


@dataclass(frozen=True, slots=True)
class FaceCapture:
    """One still capture, reduced to window means.

    Attributes
    ----------
    acc_win_mps2
        (m, 3) mean specific force of each window, m/s².
    gyr_win_radps
        (m, 3) mean angular rate of each window, rad/s.
    temp_win_c
        (m,) mean temperature of each window, °C (NaN: no temperature in the stream).
    n_samples
        Samples averaged.
    acc_noise_mps2
        Per-sample acceleration standard deviation about the window means (max axis).
    """

    acc_win_mps2: F64
    gyr_win_radps: F64
    temp_win_c: F64
    n_samples: int
    acc_noise_mps2: float

    @property
    def acc_mean_mps2(self) -> F64:
        """(3,) mean specific force of the capture."""
        return np.asarray(self.acc_win_mps2.mean(axis=0), dtype=np.float64)

    @property
    def direction(self) -> F64:
        """(3,) unit vector of the mean specific force (the face, as gravity sees it in the body frame)."""
        m = self.acc_mean_mps2
        return np.asarray(m / np.linalg.norm(m), dtype=np.float64)


def face_from_samples(
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    temp_c: F64 | None,
    rate_hz: float,
    *,
    window_s: float = WINDOW_S,
    acc_limit_mps2: float = ACC_LIMIT_MPS2,
    gyr_limit_radps: float = GYR_LIMIT_RADPS,
) -> FaceCapture:
    """Reduce one still capture (n samples) to a :class:`FaceCapture`, checking it was still.

    Parameters
    ----------
    acc_b_mps2, gyr_b_radps : ndarray, shape (n, 3)
        Samples of the capture, m/s² and rad/s.
    temp_c : ndarray, shape (n,), or None
        Sensor temperature, °C (None: not in the stream).
    rate_hz : float
        Sample rate, Hz.

    Raises
    ------
    SaturationError
        A sample is at the sensor's range.
    MotionError
        The window means vary more than a still unit's would.
    """
    acc = np.asarray(acc_b_mps2, dtype=np.float64)
    gyr = np.asarray(gyr_b_radps, dtype=np.float64)
    n = acc.shape[0]
    per = max(1, round(window_s * rate_hz))
    m = n // per
    if m < 2:
        raise MotionError(f"a still capture needs at least {2 * window_s:g} s; got {n / rate_hz:.2f} s")
    if np.any(np.abs(acc) >= acc_limit_mps2 - 1e-9) or np.any(np.abs(gyr) >= gyr_limit_radps - 1e-12):
        raise SaturationError(
            "the sensor saturated during the capture (a knock or a drop?): hold the unit still on the face "
            "and capture it again"
        )
    use = m * per
    acc_w = acc[:use].reshape(m, per, 3)
    gyr_w = gyr[:use].reshape(m, per, 3)
    acc_win = acc_w.mean(axis=1)
    gyr_win = gyr_w.mean(axis=1)
    spread_acc = float(np.max(acc_win.std(axis=0)))
    spread_gyr = float(np.max(np.abs(gyr_win - gyr_win.mean(axis=0))))
    if spread_acc > MOTION_ACC_STD_MPS2 or spread_gyr > MOTION_GYR_MEAN_RADPS:
        raise MotionError(
            f"the unit moved during the capture (acceleration varied by {spread_acc:.3f} m/s², rate by "
            f"{math.degrees(spread_gyr):.2f} °/s): hold it still on the face and capture it again"
        )
    if temp_c is None:
        temp_win = np.full(m, np.nan)
    else:
        temp_win = np.asarray(temp_c, dtype=np.float64)[:use].reshape(m, per).mean(axis=1)
    noise = float(np.max((acc_w - acc_win[:, None, :]).std(axis=(0, 1))))
    return FaceCapture(acc_win, gyr_win, temp_win, use, noise)


def distinct_faces(directions: F64, separation_deg: float = FACE_SEPARATION_DEG) -> NDArray[np.int64]:
    """Face label of each direction (k, 3): greedy clustering by angle; labels 0.. in first-seen order."""
    cos_sep = math.cos(math.radians(separation_deg))
    centres: list[F64] = []
    labels = np.empty(len(directions), dtype=np.int64)
    for i, d in enumerate(np.asarray(directions, dtype=np.float64)):
        hit = next((j for j, c in enumerate(centres) if float(c @ d) >= cos_sep), None)
        if hit is None:
            centres.append(d)
            hit = len(centres) - 1
        labels[i] = hit
    return labels


def matching_face(direction: F64, seen: list[F64], separation_deg: float = FACE_SEPARATION_DEG) -> int | None:
    """Index of the already-seen direction within ``separation_deg`` of ``direction``, else None."""
    cos_sep = math.cos(math.radians(separation_deg))
    for j, d in enumerate(seen):
        if float(np.dot(d, direction)) >= cos_sep:
            return j
    return None


# --------------------------------------------------------------------------------------- the model


def _unpack(theta: F64) -> tuple[F64, F64, F64, F64, F64]:
    """θ (15,) -> K L (3, 3), b (3,), k_T (3,), b_T (3,), k (3,)."""
    k = theta[0:3]
    low = np.eye(3)
    low[1, 0], low[2, 0], low[2, 1] = theta[3], theta[4], theta[5]
    return k[:, None] * low, theta[6:9], theta[9:12], theta[12:15], k


def invert_model(theta: F64, acc_mps2: F64, dtemp_c: F64) -> F64:
    """u = (K L + K_T ΔT)⁻¹ (y − b − b_T ΔT) for m samples: y (m, 3), ΔT (m,) -> u (m, 3).

    K L + K_T ΔT is lower triangular: forward substitution in elementwise operations, so each sample's
    result is the same bit for bit whatever batch it comes in (live and replay batch differently).
    """
    kl, b, kt, bt, _ = _unpack(np.asarray(theta, dtype=np.float64))
    dt = np.asarray(dtemp_c, dtype=np.float64)
    rhs = np.asarray(acc_mps2, dtype=np.float64) - b - dt[:, None] * bt
    diag = np.diag(kl)[None, :] + dt[:, None] * kt
    u = np.empty_like(rhs)
    u[:, 0] = rhs[:, 0] / diag[:, 0]
    u[:, 1] = (rhs[:, 1] - kl[1, 0] * u[:, 0]) / diag[:, 1]
    u[:, 2] = (rhs[:, 2] - kl[2, 0] * u[:, 0] - kl[2, 1] * u[:, 1]) / diag[:, 2]
    return u


def forward_model(theta: F64, u_mps2: F64, dtemp_c: F64) -> F64:
    """y = K L u + (K_T u + b_T) ΔT + b for m samples: u (m, 3), ΔT (m,) -> y (m, 3)."""
    kl, b, kt, bt, _ = _unpack(np.asarray(theta, dtype=np.float64))
    u = np.asarray(u_mps2, dtype=np.float64)
    dt = np.asarray(dtemp_c, dtype=np.float64)[:, None]
    return np.asarray(u @ kl.T + (u * kt + bt) * dt + b, dtype=np.float64)


@dataclass(frozen=True, slots=True)
class ImuCalibration:
    """A fitted calibration: accelerometer model θ, gyroscope bias, their 1σ, and fit quality.

    Attributes
    ----------
    theta
        (15,) accelerometer parameters in :data:`PARAM_NAMES` order.
    theta_sigma
        (15,) their 1σ (0 for parameters held fixed).
    temperature_model
        False when K_T, b_T were held at 0 (temperature unobservable or absent).
    t_ref_c
        Reference temperature, °C (mean over the procedure; NaN without temperature).
    gyr_bias_radps
        (3,) gyroscope bias at ``t_ref_c``, rad/s.
    gyr_bias_sigma_radps
        (3,) its 1σ.
    gyr_bias_slope_radps_per_c
        (3,) temperature slope of the gyroscope bias (0 if not fitted).
    residual_rms_mps2
        RMS of ``|u_j| − g`` over the windows, m/s².
    n_faces, n_windows
        Distinct faces used; residuals.
    gravity_mps2
        The ``g`` the fit assumed.
    face_residual_rms_mps2
        (n_faces,) per-face RMS residual (quality of each face).
    """

    theta: F64
    theta_sigma: F64
    temperature_model: bool
    t_ref_c: float
    gyr_bias_radps: F64
    gyr_bias_sigma_radps: F64
    gyr_bias_slope_radps_per_c: F64
    residual_rms_mps2: float
    n_faces: int
    n_windows: int
    gravity_mps2: float = STANDARD_GRAVITY_MPS2
    face_residual_rms_mps2: F64 = field(default_factory=lambda: np.zeros(0))

    @property
    def scale(self) -> F64:
        """(3,) scale factors k."""
        return self.theta[0:3]

    @property
    def misalignment_rad(self) -> F64:
        """(3,) l_yx, l_zx, l_zy (small angles, rad)."""
        return self.theta[3:6]

    @property
    def acc_bias_mps2(self) -> F64:
        """(3,) accelerometer bias at ``t_ref_c``, m/s²."""
        return self.theta[6:9]

    def well_determined(self) -> bool:
        """True when 3σ of the scale, misalignment, accelerometer and gyroscope biases are in :data:`TOLERANCE`."""
        s = self.theta_sigma
        return bool(
            np.all(3 * s[0:3] <= TOLERANCE["scale"])
            and np.all(3 * s[3:6] <= TOLERANCE["misalignment_rad"])
            and np.all(3 * s[6:9] <= TOLERANCE["acc_bias_mps2"])
            and np.all(3 * self.gyr_bias_sigma_radps <= TOLERANCE["gyr_bias_radps"])
        )

    def correct_arrays(self, acc_b_mps2: F64, gyr_b_radps: F64, temp_c: F64 | None = None) -> tuple[F64, F64]:
        """Corrected (n, 3) specific force and angular rate; ``temp_c`` (n,) or None (model at ``t_ref_c``)."""
        acc = np.asarray(acc_b_mps2, dtype=np.float64)
        n = acc.shape[0]
        if temp_c is None or not self.temperature_model:
            dt = np.zeros(n)
        else:
            dt = np.asarray(temp_c, dtype=np.float64) - self.t_ref_c
        acc_c = invert_model(self.theta, acc, dt)
        gyr_bias = self.gyr_bias_radps + dt[:, None] * self.gyr_bias_slope_radps_per_c
        gyr = np.asarray(gyr_b_radps, dtype=np.float64) - gyr_bias
        return np.asarray(acc_c, dtype=np.float64), np.asarray(gyr, dtype=np.float64)

    def correct(self, batch: ImuBatch, temp_c: F64 | None = None) -> ImuBatch:
        """The pipeline stage: ``batch`` with corrected ``acc_b_mps2`` and ``gyr_b_radps``."""
        acc, gyr = self.correct_arrays(batch.acc_b_mps2, batch.gyr_b_radps, temp_c)
        return replace(batch, acc_b_mps2=acc, gyr_b_radps=gyr)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able parameters with their 1σ and units (for the calibration file)."""

        def vec(a: F64) -> list[float]:
            return [float(x) for x in a]

        return {
            "model_version": MODEL_VERSION,
            "model": "y = K L u + (K_T u + b_T)(T - t_ref) + b; gyro: y = w + b_g + b_gT (T - t_ref)",
            "temperature_model": self.temperature_model,
            "t_ref_c": None if math.isnan(self.t_ref_c) else self.t_ref_c,
            "param_names": list(PARAM_NAMES),
            "theta": vec(self.theta),
            "theta_sigma": vec(self.theta_sigma),
            "units": "k: 1, l: rad, b: m/s^2, kt: 1/degC, bt: m/s^2/degC",
            "gyr_bias_radps": vec(self.gyr_bias_radps),
            "gyr_bias_sigma_radps": vec(self.gyr_bias_sigma_radps),
            "gyr_bias_slope_radps_per_c": vec(self.gyr_bias_slope_radps_per_c),
            "residual_rms_mps2": self.residual_rms_mps2,
            "face_residual_rms_mps2": vec(self.face_residual_rms_mps2),
            "n_faces": self.n_faces,
            "n_windows": self.n_windows,
            "gravity_mps2": self.gravity_mps2,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ImuCalibration:
        """Inverse of :meth:`to_dict`.

        Raises
        ------
        CalibrationError
            Another model version or a malformed entry.
        """
        if d.get("model_version") != MODEL_VERSION:
            raise CalibrationError(
                f"calibration model version {d.get('model_version')!r}; this footnav reads version "
                f"{MODEL_VERSION}: run `footnav calibrate` again"
            )
        try:
            t_ref = d.get("t_ref_c")
            return cls(
                theta=np.asarray(d["theta"], dtype=np.float64).reshape(15),
                theta_sigma=np.asarray(d["theta_sigma"], dtype=np.float64).reshape(15),
                temperature_model=bool(d["temperature_model"]),
                t_ref_c=float("nan") if t_ref is None else float(t_ref),
                gyr_bias_radps=np.asarray(d["gyr_bias_radps"], dtype=np.float64).reshape(3),
                gyr_bias_sigma_radps=np.asarray(d["gyr_bias_sigma_radps"], dtype=np.float64).reshape(3),
                gyr_bias_slope_radps_per_c=np.asarray(d["gyr_bias_slope_radps_per_c"], dtype=np.float64).reshape(3),
                residual_rms_mps2=float(d["residual_rms_mps2"]),
                n_faces=int(d["n_faces"]),
                n_windows=int(d["n_windows"]),
                gravity_mps2=float(d.get("gravity_mps2", STANDARD_GRAVITY_MPS2)),
                face_residual_rms_mps2=np.asarray(d.get("face_residual_rms_mps2", []), dtype=np.float64),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise CalibrationError(f"malformed calibration entry ({exc}): run `footnav calibrate` again") from exc


# ------------------------------------------------------------------------------------------ the fit


def _covariance(jac: F64, residuals: F64, rel_cond_max: float = 1e-9) -> tuple[F64, float]:
    """σ̂² (JᵀJ)⁻¹ by SVD of J (m, p); returns it and the smallest relative singular value."""
    m, p = jac.shape
    _, sv, vt = np.linalg.svd(jac, full_matrices=False)
    rel = float(sv[-1] / sv[0]) if sv[0] > 0 else 0.0
    keep = sv > rel_cond_max * sv[0]
    inv_sq = np.where(keep, 1.0 / np.where(keep, sv, 1.0) ** 2, 0.0)
    sigma2 = float(residuals @ residuals) / max(1, m - p)
    return np.asarray(sigma2 * (vt.T * inv_sq) @ vt, dtype=np.float64), rel


def check_faces(faces: list[FaceCapture], min_faces: int) -> int:
    """The number of distinct faces; raises :class:`TooFewFacesError` if too few or not spanning 3D."""
    if not faces:
        raise TooFewFacesError(f"no still face was captured: put the unit on {min_faces} or more faces in turn")
    dirs = np.array([f.direction for f in faces])
    n_distinct = int(distinct_faces(dirs).max()) + 1
    if n_distinct < min_faces:
        raise TooFewFacesError(
            f"only {n_distinct} distinct faces were captured; the model needs at least {min_faces}: "
            f"turn the unit to {min_faces - n_distinct} more faces and hold it still on each"
        )
    spread = np.linalg.eigvalsh(dirs.T @ dirs / len(dirs))
    if spread[0] < 0.05:
        raise TooFewFacesError(
            "the faces captured all lie around one plane (gravity never had a component along one axis): "
            "capture faces with the unit tilted in every direction"
        )
    return n_distinct


def fit_calibration(
    faces: list[FaceCapture],
    *,
    gravity_mps2: float = STANDARD_GRAVITY_MPS2,
    allow_no_temperature: bool = False,
    require_determined: bool = True,
) -> ImuCalibration:
    """Fit the accelerometer model and the gyroscope biases to still captures.

    Parameters
    ----------
    faces : list of FaceCapture
        One per still capture (distinct faces; repeats of a face are allowed and add windows).
    gravity_mps2 : float
        Local gravity magnitude, m/s² (default standard gravity; a local value improves the scale).
    allow_no_temperature : bool
        When the temperature barely changed or is absent: fit the 9-parameter model (K_T = b_T = 0,
        flagged in the result) instead of refusing.
    require_determined : bool
        Raise :class:`IllDeterminedError` unless :meth:`ImuCalibration.well_determined`.

    Returns
    -------
    ImuCalibration

    Raises
    ------
    TooFewFacesError, TemperatureUnobservableError, IllDeterminedError
        With what to redo.
    """
    acc = np.concatenate([f.acc_win_mps2 for f in faces]) if faces else np.zeros((0, 3))
    temp = np.concatenate([f.temp_win_c for f in faces]) if faces else np.zeros(0)
    has_temp = temp.size > 0 and bool(np.all(np.isfinite(temp)))
    spread = float(temp.max() - temp.min()) if has_temp else 0.0
    temperature_model = has_temp and spread >= MIN_TEMPERATURE_SPREAD_C
    # too few faces first: more faces may also bring the temperature spread
    check_faces(faces, MIN_FACES if (temperature_model or not allow_no_temperature) else MIN_FACES_NO_TEMPERATURE)
    if not temperature_model and not allow_no_temperature:
        why = (
            "the stream carries no temperature (use the raw IMU output with temperature)"
            if not has_temp
            else f"the temperature changed by only {spread:.1f} °C (at least {MIN_TEMPERATURE_SPREAD_C:g} °C needed)"
        )
        raise TemperatureUnobservableError(
            f"the temperature terms K_T, b_T cannot be determined: {why}. Redo the procedure while the unit "
            "warms up (start it cold, right after power-on), or accept the 9-parameter model without "
            "temperature terms (--no-temperature)"
        )
    t_ref = float(temp.mean()) if has_temp else float("nan")
    dt = temp - t_ref if has_temp else np.zeros(len(acc))
    face_of = np.concatenate([np.full(len(f.acc_win_mps2), i) for i, f in enumerate(faces)])
    free = np.arange(15) if temperature_model else np.arange(9)
    theta0 = np.zeros(15)
    theta0[0:3] = 1.0

    def full(x: F64) -> F64:
        th = theta0.copy()
        th[free] = x
        return th

    def residuals(x: F64) -> F64:
        u = invert_model(full(x), acc, dt)
        return np.asarray(np.linalg.norm(u, axis=1) - gravity_mps2, dtype=np.float64)

    from scipy.optimize import least_squares  # here, not at the top: importing it takes about a second

    sol = least_squares(residuals, theta0[free], method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    res = np.asarray(sol.fun, dtype=np.float64)
    cov, rel_sv = _covariance(np.asarray(sol.jac, dtype=np.float64), res)
    theta = full(np.asarray(sol.x, dtype=np.float64))
    sigma = np.zeros(15)
    sigma[free] = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    face_rms = np.array([math.sqrt(float(np.mean(res[face_of == i] ** 2))) for i in range(len(faces))])
    gyr_bias, gyr_sigma, gyr_slope = fit_gyro_bias(faces, dt, fit_slope=temperature_model)
    cal = ImuCalibration(
        theta=theta,
        theta_sigma=sigma,
        temperature_model=temperature_model,
        t_ref_c=t_ref,
        gyr_bias_radps=gyr_bias,
        gyr_bias_sigma_radps=gyr_sigma,
        gyr_bias_slope_radps_per_c=gyr_slope,
        residual_rms_mps2=math.sqrt(float(np.mean(res**2))),
        n_faces=int(distinct_faces(np.array([f.direction for f in faces])).max()) + 1,
        n_windows=len(res),
        gravity_mps2=gravity_mps2,
        face_residual_rms_mps2=face_rms,
    )
    if rel_sv < 1e-9:
        raise IllDeterminedError(
            "the captures do not determine every parameter (singular fit): capture more distinct faces"
        )
    if require_determined and not cal.well_determined():
        raise IllDeterminedError(
            "the fit is not well determined yet (3σ of scale "
            f"{3e2 * sigma[0:3].max():.3f} %, misalignment {math.degrees(3 * sigma[3:6].max()):.3f}°, bias "
            f"{3e3 * sigma[6:9].max() / STANDARD_GRAVITY_MPS2:.2f} mg): capture more faces, each still for longer"
        )
    return cal


def fit_gyro_bias(faces: list[FaceCapture], dtemp_c: F64, *, fit_slope: bool) -> tuple[F64, F64, F64]:
    """Gyroscope bias (3,), its 1σ (3,) and temperature slope (3,) from the still captures.

    Each capture's mean rate is ``b_g + b_gT ΔT + noise``: linear least squares per axis over the
    captures (the slope only with ``fit_slope``). The 1σ comes from the scatter of the capture means
    about the fit, so slow in-run drift, which makes windows of one capture agree too well, is counted.

    ``dtemp_c``: (m,) the windows' ``T − t_ref`` in the order of the captures' windows.
    """
    sizes = [len(f.gyr_win_radps) for f in faces]
    gyr = np.array([f.gyr_win_radps.mean(axis=0) for f in faces])
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    dt = np.array([float(np.mean(dtemp_c[a : a + m])) for a, m in zip(starts, sizes, strict=True)])
    k = gyr.shape[0]
    design = np.column_stack([np.ones(k), dt]) if fit_slope else np.ones((k, 1))
    coef, *_ = np.linalg.lstsq(design, gyr, rcond=None)
    res = gyr - design @ coef
    dof = max(1, k - design.shape[1])
    sigma2 = (res**2).sum(axis=0) / dof
    _, sv, vt = np.linalg.svd(design, full_matrices=False)
    var_b = float(((vt[:, 0] / sv) ** 2).sum())  # (DᵀD)⁻¹[0, 0]
    slope = coef[1] if fit_slope else np.zeros(3)
    return np.asarray(coef[0], dtype=np.float64), np.sqrt(sigma2 * var_b), np.asarray(slope, dtype=np.float64)
