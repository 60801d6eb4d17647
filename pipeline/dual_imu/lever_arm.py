"""Is the configured lever arm the board's? A χ² check of the rigid-body specific-force relation.

For two IMUs on one rigid board (parallel axes, IMU 2 at ``m`` in IMU 1's axes; Groves 2013 §2.5)::

    f₂ − f₁ = ω̇ × m + ω × (ω × m) + (b_a2 − b_a1) + n  =  A(ω, ω̇) m + Δb + n,
    A(ω, ω̇) = [ω̇]× + [ω]×²

which is linear in ``m``. In swing (|ω| of several rad/s, |ω̇| of tens of rad/s²) the lever-arm
terms are tenths of m/s² for a 1.4 cm arm, well above the noise of the difference. Per sample:

- ``ω`` = the averaged rate, ``ω̇`` its central difference over ±``half_window`` samples (a monitor,
  so a few ms of look-ahead are fine);
- ``Δb`` = the mean of ``f₂ − f₁`` over the stance samples so far (the arm terms vanish at rest);
- residual ``e = f₂ − f₁ − Δb − A m`` and its NIS ``eᵀ e / σ²`` with ``σ² = 2 σ_f²`` per axis;
- samples where either IMU is not finite or at full scale, and their neighbours within the
  difference stencil, are left out.

The NIS summed over windows of ``window_s`` of swing is χ² with 3 × (samples) degrees of freedom
when the lever arm is right (Bar-Shalom et al. 2001 §5.4); windows above the ``1 − alpha`` quantile
are flagged, and the verdict is "disagrees" when more than ``max_flagged_fraction`` of them are. The
least-squares lever arm from the same relation, ``(Σ AᵀA)⁻¹ Σ Aᵀ (f₂ − f₁ − Δb)``, says what the
data think it is, with covariance ``σ² (Σ AᵀA)⁻¹``.

Verdict: the configured arm disagrees when the least-squares arm differs from it both
statistically (``d² = δmᵀ (Σ AᵀA) δm / σ²`` above the χ²(3) ``1 − alpha`` quantile) and physically
(by more than ``tolerance_m``: model errors a few tenths of a millimetre must not raise alarms), or
when more than ``max_flagged_fraction`` of the windows fail. The windows catch an arm that is wrong
along the axes the gait rotates the board about most; the least-squares test also catches one wrong
along the pitch axis, where a foot's rotation hardly moves the lever-arm terms.

References
----------
- Groves, P. D. (2013). *Principles of GNSS, Inertial, and Multisensor Integrated Navigation
  Systems*, 2nd ed., §2.5.
- Bar-Shalom, Li and Kirubarajan (2001). *Estimation with Applications to Tracking and
  Navigation*, §5.4 (NIS, χ² acceptance regions).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from footnav.pipeline.dual_imu.model import ACC_FULL_SCALE_MPS2, GYR_FULL_SCALE_RADPS
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class LeverArmCheck:
    """Result of :func:`check_lever_arm`.

    Attributes
    ----------
    configured_b_m
        (3,) the lever arm that was checked, m.
    estimated_b_m
        (3,) least-squares lever arm from the data, m.
    estimated_sigma_b_m
        (3,) its 1σ, m.
    window_t_s
        (w,) end time of each swing window, s.
    window_nis
        (w,) NIS summed over each window.
    window_bound
        (w,) the χ² ``1 − alpha`` quantile of each window.
    nis
        (n,) per-sample NIS (NaN where not formed: stance, slow rotation, a bad sample).
    flagged_fraction
        share of windows above their bound.
    distance2
        ``d²`` of the least-squares arm from the configured one (module docstring).
    consistent
        the configured lever arm agrees with the data (True when nothing could be tested).
    """

    configured_b_m: F64
    estimated_b_m: F64
    estimated_sigma_b_m: F64
    window_t_s: F64
    window_nis: F64
    window_bound: F64
    nis: F64
    flagged_fraction: float
    distance2: float
    consistent: bool

    @property
    def message(self) -> str:
        """One line a person can act on."""
        conf = np.array2string(self.configured_b_m * 100.0, precision=2, suppress_small=True)
        est = np.array2string(self.estimated_b_m * 100.0, precision=2, suppress_small=True)
        sig = float(np.max(self.estimated_sigma_b_m)) * 100.0
        if self.window_nis.size == 0:
            return f"lever arm {conf} cm not checked yet: no swing with rotation in the record"
        if self.consistent:
            return f"lever arm {conf} cm agrees with the data (estimated {est} cm ± {sig:.2f} cm)"
        return (
            f"lever arm {conf} cm disagrees with the data: {self.flagged_fraction:.0%} of swing windows fail the "
            f"χ² test (least-squares d² = {self.distance2:.0f}); the data say {est} cm ± {sig:.2f} cm. "
            "Is the board mounted differently? "
            "Set the lever arm to the board's."
        )


def _skew(v: F64) -> F64:
    """(n, 3) -> (n, 3, 3) cross-product matrices, ``[v]× u = v × u``."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def check_lever_arm(
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    stance: NDArray[np.bool_],
    lever_b_m: F64,
    rate_hz: float,
    *,
    sigma_acc_mps2: float,
    window_s: float = 1.0,
    half_window: int = 5,
    min_rate_radps: float = 1.0,
    alpha: float = 1e-3,
    max_flagged_fraction: float = 0.2,
    tolerance_m: float = 2e-3,
) -> LeverArmCheck:
    """Check ``lever_b_m`` against a dual-IMU record (module docstring).

    Parameters
    ----------
    acc_b_mps2, gyr_b_radps : ndarray, shape (n, 2, 3)
        IMU 1 and IMU 2 measurements, m/s² and rad/s.
    stance : ndarray of bool, shape (n,)
        Zero-velocity detector output.
    lever_b_m : ndarray, shape (3,)
        The configured lever arm, m.
    rate_hz : float
        Sample rate, Hz.
    sigma_acc_mps2 : float
        Per-sample white-noise 1σ of one accelerometer axis, m/s².
    window_s : float
        Swing time summed per window, s.
    """
    acc = np.asarray(acc_b_mps2, dtype=np.float64)
    gyr = np.asarray(gyr_b_radps, dtype=np.float64)
    m = np.asarray(lever_b_m, dtype=np.float64).reshape(3)
    n = acc.shape[0]
    h = half_window
    # usable: finite and below full scale on both IMUs (a saturated reading is not the motion)
    with np.errstate(invalid="ignore"):
        ok = np.all(np.abs(acc) < ACC_FULL_SCALE_MPS2, axis=(1, 2)) & np.all(
            np.abs(gyr) < GYR_FULL_SCALE_RADPS, axis=(1, 2)
        )
    w = np.where(ok[:, None], gyr.mean(axis=1), np.nan)
    wdot = np.full((n, 3), np.nan)
    wdot[h : n - h] = (w[2 * h :] - w[: n - 2 * h]) * (rate_hz / (2 * h))
    diff = acc[:, 1] - acc[:, 0]
    still = stance & ok
    counts = np.cumsum(still)
    sums = np.cumsum(np.where(still[:, None], diff, 0.0), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        bias_diff = sums / counts[:, None]
    A = _skew(np.nan_to_num(wdot)) + _skew(np.nan_to_num(w)) @ _skew(np.nan_to_num(w))
    rate = np.linalg.norm(w, axis=1)
    use = ~stance & ok & (counts > 0) & np.all(np.isfinite(wdot), axis=1) & (np.nan_to_num(rate) >= min_rate_radps)
    # a window's samples must all be usable: neighbours of a bad sample are dropped as well
    bad_near = np.convolve((~ok).astype(np.float64), np.ones(2 * h + 1), mode="same") > 0
    use &= ~bad_near
    rhs = diff - bias_diff
    e = rhs - np.einsum("nij,j->ni", A, m)
    var = 2.0 * sigma_acc_mps2**2
    nis = np.full(n, np.nan)
    nis[use] = np.sum(e[use] ** 2, axis=1) / var
    idx = np.flatnonzero(use)
    per_window = max(1, round(window_s * rate_hz))
    n_win = idx.size // per_window
    win_nis = np.array([nis[idx[i * per_window : (i + 1) * per_window]].sum() for i in range(n_win)])
    win_t = np.array([idx[(i + 1) * per_window - 1] / rate_hz for i in range(n_win)])
    from scipy.stats import chi2  # here, not at the top: importing scipy.stats takes about a second

    bound = np.full(n_win, float(chi2.ppf(1.0 - alpha, 3 * per_window)))
    flagged = float(np.mean(win_nis > bound)) if n_win else 0.0
    Au = A[use]
    normal = np.einsum("nki,nkj->ij", Au, Au)
    if idx.size >= 3 and np.linalg.cond(normal) < 1e8:
        est = np.linalg.solve(normal, np.einsum("nki,nk->i", Au, rhs[use]))
        sig = np.sqrt(np.diag(np.linalg.inv(normal)) * var)
        delta = est - m
        d2 = float(delta @ normal @ delta / var)
        far = d2 > float(chi2.ppf(1.0 - alpha, 3)) and float(np.linalg.norm(delta)) > tolerance_m
    else:
        est, sig, d2, far = np.full(3, np.nan), np.full(3, np.inf), 0.0, False
    return LeverArmCheck(
        configured_b_m=m,
        estimated_b_m=est,
        estimated_sigma_b_m=sig,
        window_t_s=win_t,
        window_nis=win_nis,
        window_bound=bound,
        nis=nis,
        flagged_fraction=flagged,
        distance2=d2,
        consistent=bool(flagged <= max_flagged_fraction and not far),
    )
