"""IMU error model: white noise plus a turn-on bias and an in-run bias drift, per axis.

Measured signal, per sensor (accelerometer or gyroscope) and axis, at sample ``k``::

    y_k = M x_k + b_0 + d_k + w_k

- ``x_k``: the true signal (specific force, m/s², or angular rate, rad/s, in body axes);
- ``M = (I + diag(s)) + N``: optional axis errors (:class:`AxisErrors`), drawn once per run: scale-factor errors
  ``s`` and cross-axis sensitivities ``N`` (zero diagonal; ``N_ij`` the fraction of axis j's input read by axis i,
  as datasheets define it); identity by default;
- ``b_0``: the turn-on (residual) bias, constant over a run, drawn from N(0, σ_b0²);
- ``d_k``: the in-run bias drift, a first-order Gauss-Markov process with stationary standard deviation the
  datasheet bias instability σ_bi and correlation time τ_c (:data:`BIAS_CORRELATION_TIME_S`):
  ``d_{k+1} = φ d_k + √(1 − φ²) σ_bi ε_k``, ``φ = exp(−Δt/τ_c)``, started from its stationary distribution (driving
  density ``σ_bi √(2/τ_c)`` per √s);
- ``w_k``: white noise, independent between samples.

Optionally the gyroscope lags the accelerometer by a constant ``gyr_delay_s`` = τ (:func:`corrupt`): its true
signal is read at ``t_k − τ`` (linear interpolation, held at the first and last sample beyond the ends), and the
output saturates at a full scale and is quantised by the ADC (:class:`FullScale`): ``clip(y, ±FS)`` rounded to
``FS / 2^(bits−1)``.

Noise densities are *one-sided* spectral densities as datasheets give them (RMS noise = density × √bandwidth).
Samples are taken without an anti-alias filter, so the noise bandwidth is the Nyquist frequency and the per-sample
standard deviation is ``σ_w = density × √(rate / 2)``. A random-walk coefficient N (ARW in °/√h, VRW in m/s/√h,
the Allan deviation at 1 s) is ``density = √2 × N``; integrating the simulated noise then gives a random walk of
exactly ``N √t``. Not modelled: g-sensitivity, nonlinearity, quantisation, temperature (the accelerometer's
temperature model is :class:`footnav.device.emulator.sensors.icosahedron.Miscalibration`). Why these terms and
values: the documentation's design page "Emulator".

References: IEEE Std 952-1997 (Allan variance, random walk and bias instability terms); Groves, P. D. (2013),
*Principles of GNSS, Inertial, and Multisensor Integrated Navigation Systems*, 2nd ed., §4.4 and §14.2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

STANDARD_GRAVITY_MPS2 = 9.80665
"""1 g, m/s² (3rd CGPM, 1901), for converting datasheet mg and µg figures."""

BIAS_CORRELATION_TIME_S = 100.0
"""Correlation time of the Gauss-Markov in-run bias drift, s (an assumption; none is specified)."""

_DEG = math.pi / 180.0
_MG = 1e-3 * STANDARD_GRAVITY_MPS2
_UG = 1e-6 * STANDARD_GRAVITY_MPS2
_SQRT_H = 60.0  # √(3600 s): divides a per-√h figure into a per-√s one


@dataclass(frozen=True, slots=True)
class ImuGrade:
    """Error magnitudes of one IMU, the same for all three axes of each sensor.

    Attributes
    ----------
    name
        Short identifier (the key in :data:`IMU_GRADES`).
    acc_noise_density_mps2_rthz
        Accelerometer white noise, one-sided density, m/s²/√Hz.
    gyr_noise_density_radps_rthz
        Gyroscope white noise, one-sided density, rad/s/√Hz.
    acc_bias_sigma_mps2
        Accelerometer turn-on (residual) bias, 1σ per axis, m/s².
    gyr_bias_sigma_radps
        Gyroscope turn-on (residual) bias, 1σ per axis, rad/s.
    acc_bias_instability_mps2
        Accelerometer in-run bias drift, stationary 1σ, m/s².
    gyr_bias_instability_radps
        Gyroscope in-run bias drift, stationary 1σ, rad/s.
    bias_correlation_time_s
        Correlation time of the in-run drift, s.
    """

    name: str
    acc_noise_density_mps2_rthz: float
    gyr_noise_density_radps_rthz: float
    acc_bias_sigma_mps2: float
    gyr_bias_sigma_radps: float
    acc_bias_instability_mps2: float
    gyr_bias_instability_radps: float
    bias_correlation_time_s: float = BIAS_CORRELATION_TIME_S

    def acc_noise_sigma_mps2(self, rate_hz: float) -> float:
        """Per-sample accelerometer white-noise standard deviation at ``rate_hz``, m/s²."""
        return self.acc_noise_density_mps2_rthz * math.sqrt(0.5 * rate_hz)

    def gyr_noise_sigma_radps(self, rate_hz: float) -> float:
        """Per-sample gyroscope white-noise standard deviation at ``rate_hz``, rad/s."""
        return self.gyr_noise_density_radps_rthz * math.sqrt(0.5 * rate_hz)


IMU_GRADES: dict[str, ImuGrade] = {
    # GT Silicon MIMU22BL / Oblu: four InvenSense MPU-6500 averaged on one board. MPU-6500 datasheet
    # (PS-MPU-6500A-01, rev 1.1): gyro rate noise 0.01 °/s/√Hz, accel noise 300 µg/√Hz; averaging four
    # independent sensors halves both. Residual turn-on biases after the maker's factory calibration
    # (0.1 °/s, 5 mg) and the in-run drift (10 °/h, 0.1 mg) are assumptions, not datasheet values.
    "mpu6500x4": ImuGrade(
        name="mpu6500x4",
        acc_noise_density_mps2_rthz=300.0 * _UG / 2.0,
        gyr_noise_density_radps_rthz=0.01 * _DEG / 2.0,
        acc_bias_sigma_mps2=5.0 * _MG,
        gyr_bias_sigma_radps=0.1 * _DEG,
        acc_bias_instability_mps2=0.1 * _MG,
        gyr_bias_instability_radps=10.0 / 3600.0 * _DEG,
    ),
    # Analog Devices ADIS16367 (OpenShoe), datasheet rev. B: angular random walk 2 °/√h, in-run
    # bias stability 0.007 °/s; velocity random walk 0.2 m/s/√h, accel in-run bias stability 0.1 mg.
    # Residual turn-on biases after the usual OpenShoe calibration (0.05 °/s, 2 mg) are assumptions.
    "adis16367": ImuGrade(
        name="adis16367",
        acc_noise_density_mps2_rthz=math.sqrt(2.0) * 0.2 / _SQRT_H,
        gyr_noise_density_radps_rthz=math.sqrt(2.0) * 2.0 / _SQRT_H * _DEG,
        acc_bias_sigma_mps2=2.0 * _MG,
        gyr_bias_sigma_radps=0.05 * _DEG,
        acc_bias_instability_mps2=0.1 * _MG,
        gyr_bias_instability_radps=0.007 * _DEG,
    ),
    # TDK InvenSense ICM-20948, datasheet DS-000189 rev 1.3: gyro rate noise 0.015 °/s/√Hz, accel
    # noise 230 µg/√Hz. Residual turn-on biases after a start-up calibration (0.1 °/s, 10 mg) and the
    # in-run drift (20 °/h, 0.1 mg) are assumptions.
    "icm20948": ImuGrade(
        name="icm20948",
        acc_noise_density_mps2_rthz=230.0 * _UG,
        gyr_noise_density_radps_rthz=0.015 * _DEG,
        acc_bias_sigma_mps2=10.0 * _MG,
        gyr_bias_sigma_radps=0.1 * _DEG,
        acc_bias_instability_mps2=0.1 * _MG,
        gyr_bias_instability_radps=20.0 / 3600.0 * _DEG,
    ),
    # The same part uncalibrated on its board, as the dual-IMU paper's (Chen et al. 2022) used it:
    # DS-000189 rev 1.3 accelerometer zero-g initial tolerance, board level, ±50 mg, taken as 1σ (an
    # assumption: the datasheet gives a typical value). The gyro's ±5 °/s initial zero-rate offset is
    # removed by the start-up calibration every filter here gets; 0.1 °/s residual as above.
    "icm20948-board": ImuGrade(
        name="icm20948-board",
        acc_noise_density_mps2_rthz=230.0 * _UG,
        gyr_noise_density_radps_rthz=0.015 * _DEG,
        acc_bias_sigma_mps2=50.0 * _MG,
        gyr_bias_sigma_radps=0.1 * _DEG,
        acc_bias_instability_mps2=0.1 * _MG,
        gyr_bias_instability_radps=20.0 / 3600.0 * _DEG,
    ),
    # LORD MicroStrain 3DM-GX3-25, product datasheet (typical values as listed there; re-check
    # against the revision in use): gyro noise density 0.03 °/s/√Hz, in-run bias stability 18 °/h,
    # initial bias ±0.25 °/s; accel noise density 80 µg/√Hz, in-run bias stability 0.04 mg,
    # initial bias ±0.002 g (taken as 1σ here).
    "gx3": ImuGrade(
        name="gx3",
        acc_noise_density_mps2_rthz=80.0 * _UG,
        gyr_noise_density_radps_rthz=0.03 * _DEG,
        acc_bias_sigma_mps2=2.0 * _MG,
        gyr_bias_sigma_radps=0.25 * _DEG,
        acc_bias_instability_mps2=0.04 * _MG,
        gyr_bias_instability_radps=18.0 / 3600.0 * _DEG,
    ),
    # No errors at all: corrupt() returns the truth unchanged.
    "ideal": ImuGrade(
        name="ideal",
        acc_noise_density_mps2_rthz=0.0,
        gyr_noise_density_radps_rthz=0.0,
        acc_bias_sigma_mps2=0.0,
        gyr_bias_sigma_radps=0.0,
        acc_bias_instability_mps2=0.0,
        gyr_bias_instability_radps=0.0,
    ),
}
"""Named IMU grades. Datasheet figures are cited per entry; the rest are marked as assumptions."""


@dataclass(frozen=True, slots=True)
class AxisErrors:
    """Scale-factor and cross-axis errors of one unit's sensors, 1σ per element (dimensionless).

    Attributes
    ----------
    name
        Short identifier (the key in :data:`AXIS_ERRORS`).
    acc_scale_sigma
        Accelerometer scale-factor error per axis (0.01 = 1 %).
    acc_cross_axis_sigma
        Accelerometer cross-axis sensitivity per off-diagonal element.
    gyr_scale_sigma
        Gyroscope scale-factor error per axis.
    gyr_cross_axis_sigma
        Gyroscope cross-axis sensitivity per off-diagonal element.
    """

    name: str
    acc_scale_sigma: float
    acc_cross_axis_sigma: float
    gyr_scale_sigma: float
    gyr_cross_axis_sigma: float

    def draw(self, seed: int) -> tuple[F64, F64]:
        """(accelerometer, gyroscope) (3, 3) axis-error matrices ``M`` of the run seeded ``seed``.

        Drawn from their own stream (``default_rng([seed, 1])``), so adding axis errors leaves the
        biases and noise of the same seed unchanged."""
        rng = np.random.default_rng([seed, 1])
        off = 1.0 - np.eye(3)
        mats = []
        for scale, cross in (
            (self.acc_scale_sigma, self.acc_cross_axis_sigma),
            (self.gyr_scale_sigma, self.gyr_cross_axis_sigma),
        ):
            mats.append(np.eye(3) + np.diag(scale * rng.standard_normal(3)) + cross * off * rng.standard_normal((3, 3)))
        return mats[0], mats[1]


AXIS_ERRORS: dict[str, AxisErrors] = {
    "none": AxisErrors("none", 0.0, 0.0, 0.0, 0.0),
    # A consumer MEMS unit whose accelerometer was calibrated on the icosahedron jig (15 parameters)
    # and whose gyroscope had only its bias calibrated. Accelerometer residual: 0.01 % scale and
    # 0.02 % (0.011°) cross-axis, 1σ (an assumption, design page "Emulator"). Gyroscope: the
    # MPU-6500 datasheet (PS-MPU-6500A-01 rev 1.1) sensitivity scale factor tolerance ±3 % and
    # cross-axis sensitivity ±2 %, taken as 3σ (an assumption: the datasheet gives typical limits).
    "gyro-bias-calibrated": AxisErrors(
        "gyro-bias-calibrated",
        acc_scale_sigma=1e-4,
        acc_cross_axis_sigma=2e-4,
        gyr_scale_sigma=0.03 / 3.0,
        gyr_cross_axis_sigma=0.02 / 3.0,
    ),
    # An uncalibrated TDK ICM-20948 (the dual-IMU paper's part), datasheet DS-000189 rev 1.3 typical
    # values taken as 1σ (an assumption): accelerometer sensitivity initial tolerance ±0.5 % and
    # cross-axis sensitivity ±2 %; gyroscope sensitivity initial tolerance ±1.5 % and cross-axis ±2 %.
    "icm20948-datasheet": AxisErrors(
        "icm20948-datasheet",
        acc_scale_sigma=0.005,
        acc_cross_axis_sigma=0.02,
        gyr_scale_sigma=0.015,
        gyr_cross_axis_sigma=0.02,
    ),
}
"""Named axis-error (calibration residual) settings; sources and assumptions per entry."""


@dataclass(frozen=True, slots=True)
class FullScale:
    """An IMU's output range and ADC: readings beyond ±full scale saturate, the rest are quantised.

    Attributes
    ----------
    acc_mps2
        Accelerometer full scale, m/s² (readings clip to ±acc_mps2).
    gyr_radps
        Gyroscope full scale, rad/s.
    bits
        ADC word length, two's complement: one step is full scale / 2^(bits − 1).
    """

    acc_mps2: float
    gyr_radps: float
    bits: int = 16

    def apply(self, acc_b_mps2: F64, gyr_b_radps: F64) -> tuple[F64, F64, int, int]:
        """(acc, gyr) (n, 3) saturated and quantised, and how many samples clipped on each sensor."""
        out = []
        clipped = []
        for y, fs in ((acc_b_mps2, self.acc_mps2), (gyr_b_radps, self.gyr_radps)):
            over = np.abs(y) > fs
            clipped.append(int(np.count_nonzero(over.any(axis=1))))
            step = fs / 2.0 ** (self.bits - 1)
            out.append(np.round(np.clip(y, -fs, fs) / step) * step)
        return out[0], out[1], clipped[0], clipped[1]


ICM20948_PAPER_RANGE = FullScale(acc_mps2=8.0 * STANDARD_GRAVITY_MPS2, gyr_radps=1000.0 * _DEG)
"""The dual-IMU paper's ICM-20948 setting: ±8 g, ±1000 °/s, 16-bit ADCs (DS-000189 rev 1.3, §3.1-3.2)."""


@dataclass(frozen=True, slots=True)
class ImuErrorsApplied:
    """The errors :func:`corrupt` added, so that tests and evaluations can subtract or check them.

    Attributes
    ----------
    grade
        The grade the errors were drawn from.
    rate_hz
        Sample rate, Hz.
    acc_bias_b_mps2
        (n, 3) total accelerometer bias (turn-on + drift) at each sample, m/s².
    gyr_bias_b_radps
        (n, 3) total gyroscope bias at each sample, rad/s.
    acc_turn_on_bias_b_mps2
        (3,) accelerometer turn-on bias, m/s².
    gyr_turn_on_bias_b_radps
        (3,) gyroscope turn-on bias, rad/s.
    acc_noise_b_mps2
        (n, 3) accelerometer white noise added, m/s².
    gyr_noise_b_radps
        (n, 3) gyroscope white noise added, rad/s.
    acc_axes
        (3, 3) accelerometer axis-error matrix applied (identity: none).
    gyr_axes
        (3, 3) gyroscope axis-error matrix applied.
    acc_clipped, gyr_clipped
        Samples whose reading saturated (any axis) on each sensor (0 without a full scale).
    """

    grade: ImuGrade
    rate_hz: float
    acc_bias_b_mps2: F64
    gyr_bias_b_radps: F64
    acc_turn_on_bias_b_mps2: F64
    gyr_turn_on_bias_b_radps: F64
    acc_noise_b_mps2: F64
    gyr_noise_b_radps: F64
    acc_axes: F64
    gyr_axes: F64
    acc_clipped: int = 0
    gyr_clipped: int = 0


def gauss_markov(
    n: int, sigma: float, corr_time_s: float, rate_hz: float, *, rng: np.random.Generator, n_axes: int = 3
) -> F64:
    """Stationary first-order Gauss-Markov sequences, vectorised.

    ``d_{k+1} = φ d_k + √(1 − φ²) σ ε_k`` with ``φ = exp(−1 / (rate τ_c))``, ``d_0 ~ N(0, σ²)``.
    Solved in closed form block by block, ``d_k = φ^k (d_0 + Σ_{j<k} φ^{−(j+1)} e_j)``, with blocks
    short enough that ``φ^{−k}`` stays below e^20.

    Parameters
    ----------
    n : int
        Number of samples.
    sigma : float
        Stationary standard deviation (units of the output).
    corr_time_s : float
        Correlation time, s (> 0).
    rate_hz : float
        Sample rate, Hz.
    rng : numpy.random.Generator
        Source of randomness.
    n_axes : int
        Number of independent sequences (columns).

    Returns
    -------
    ndarray, shape (n, n_axes)
    """
    out = np.zeros((n, n_axes))
    if n == 0 or sigma == 0.0:
        return out
    decay = 1.0 / (rate_hz * corr_time_s)
    phi = math.exp(-decay)
    drive = sigma * math.sqrt(-math.expm1(-2.0 * decay))
    e = drive * rng.standard_normal((n, n_axes))
    block = max(1, int(20.0 / decay))
    state = sigma * rng.standard_normal(n_axes)
    for start in range(0, n, block):
        stop = min(n, start + block)
        k = np.arange(stop - start, dtype=np.float64)[:, None]
        # d_{start + k} = φ^k (state + Σ_{j<k} φ^{-(j+1)} e_{start + j})
        grow = np.exp((k + 1.0) * decay)
        acc = np.cumsum(e[start:stop] * grow, axis=0)
        shrink = np.exp(-k * decay)
        out[start] = state
        out[start + 1 : stop] = shrink[1:] * (state + acc[:-1])
        state = phi * out[stop - 1] + e[stop - 1]
    return out


def delayed(signal: F64, rate_hz: float, delay_s: float) -> F64:
    """``signal`` (n, m), sampled at ``rate_hz``, read ``delay_s`` later: row k is the signal at
    sample time ``t_k − delay_s``, interpolated linearly between samples and held beyond the ends
    (a negative delay reads ahead). A delay of 0 returns the same values."""
    n = signal.shape[0]
    if delay_s == 0.0 or n < 2:
        return signal
    pos = np.clip(np.arange(n, dtype=np.float64) - delay_s * rate_hz, 0.0, n - 1.0)
    i0 = np.minimum(np.floor(pos).astype(np.int64), n - 2)
    w = (pos - i0)[:, None]
    out: F64 = (1.0 - w) * signal[i0] + w * signal[i0 + 1]
    return out


def corrupt(
    truth_acc_b: F64,
    truth_gyr_b: F64,
    rate_hz: float,
    grade: ImuGrade | str,
    seed: int,
    *,
    gyr_delay_s: float = 0.0,
    axes: AxisErrors | str = "none",
    full_scale: FullScale | None = None,
) -> tuple[F64, F64, ImuErrorsApplied]:
    """Add a grade's errors to true IMU signals.

    Parameters
    ----------
    truth_acc_b : ndarray, shape (n, 3)
        True specific force in body axes, m/s².
    truth_gyr_b : ndarray, shape (n, 3)
        True angular rate in body axes, rad/s.
    rate_hz : float
        Sample rate, Hz (sets the per-sample noise, see the module docstring).
    grade : ImuGrade or str
        The error magnitudes, or a key of :data:`IMU_GRADES`.
    seed : int
        Seed for ``numpy.random.default_rng``; the same seed gives the same errors.
    gyr_delay_s : float
        The gyroscope lags the accelerometer by this much, s (module docstring; 0: no delay, the
        default). Biases and noise are added after the delay.
    axes : AxisErrors or str
        Scale-factor and cross-axis errors (or a key of :data:`AXIS_ERRORS`), applied to the true
        signals first (module docstring). Default ``"none"``.
    full_scale : FullScale or None
        The output range and ADC the readings pass through last (None: unbounded, unquantised).

    Returns
    -------
    acc_b_mps2 : ndarray, shape (n, 3)
        Measured specific force, m/s².
    gyr_b_radps : ndarray, shape (n, 3)
        Measured angular rate, rad/s.
    applied : ImuErrorsApplied
        The biases and noise that were added.

    Raises
    ------
    ValueError
        On an unknown grade or axis-error name, mismatched or non-(n, 3) inputs, or a non-positive rate.
    """
    if isinstance(grade, str):
        try:
            grade = IMU_GRADES[grade]
        except KeyError:
            raise ValueError(f"unknown IMU grade {grade!r}; expected one of {sorted(IMU_GRADES)}") from None
    if isinstance(axes, str):
        try:
            axes = AXIS_ERRORS[axes]
        except KeyError:
            raise ValueError(f"unknown axis errors {axes!r}; expected one of {sorted(AXIS_ERRORS)}") from None
    acc_in = np.asarray(truth_acc_b, dtype=np.float64)
    gyr_in = np.asarray(truth_gyr_b, dtype=np.float64)
    if acc_in.ndim != 2 or acc_in.shape[1] != 3 or acc_in.shape != gyr_in.shape:
        raise ValueError(f"expected two (n, 3) arrays of the same shape, got {acc_in.shape} and {gyr_in.shape}")
    if not rate_hz > 0.0:
        raise ValueError(f"sample rate must be positive, got {rate_hz} Hz")
    if not math.isfinite(gyr_delay_s):
        raise ValueError(f"gyroscope delay must be finite, got {gyr_delay_s} s")
    acc_axes, gyr_axes = axes.draw(seed)
    if not np.array_equal(acc_axes, np.eye(3)):
        acc_in = acc_in @ acc_axes.T
    if not np.array_equal(gyr_axes, np.eye(3)):
        gyr_in = gyr_in @ gyr_axes.T
    gyr_in = delayed(gyr_in, rate_hz, gyr_delay_s)
    n = acc_in.shape[0]
    rng = np.random.default_rng(seed)
    acc_turn_on = grade.acc_bias_sigma_mps2 * rng.standard_normal(3)
    gyr_turn_on = grade.gyr_bias_sigma_radps * rng.standard_normal(3)
    acc_drift = gauss_markov(n, grade.acc_bias_instability_mps2, grade.bias_correlation_time_s, rate_hz, rng=rng)
    gyr_drift = gauss_markov(n, grade.gyr_bias_instability_radps, grade.bias_correlation_time_s, rate_hz, rng=rng)
    acc_noise = grade.acc_noise_sigma_mps2(rate_hz) * rng.standard_normal((n, 3))
    gyr_noise = grade.gyr_noise_sigma_radps(rate_hz) * rng.standard_normal((n, 3))
    acc_bias = acc_turn_on + acc_drift
    gyr_bias = gyr_turn_on + gyr_drift
    acc_out, gyr_out = acc_in + acc_bias + acc_noise, gyr_in + gyr_bias + gyr_noise
    acc_clipped = gyr_clipped = 0
    if full_scale is not None:
        acc_out, gyr_out, acc_clipped, gyr_clipped = full_scale.apply(acc_out, gyr_out)
    applied = ImuErrorsApplied(
        grade=grade,
        rate_hz=float(rate_hz),
        acc_bias_b_mps2=acc_bias,
        gyr_bias_b_radps=gyr_bias,
        acc_turn_on_bias_b_mps2=acc_turn_on,
        gyr_turn_on_bias_b_radps=gyr_turn_on,
        acc_noise_b_mps2=acc_noise,
        gyr_noise_b_radps=gyr_noise,
        acc_axes=acc_axes,
        gyr_axes=gyr_axes,
        acc_clipped=acc_clipped,
        gyr_clipped=gyr_clipped,
    )
    return acc_out, gyr_out, applied
