"""Dense Kalman-filter steps for the small filters of the dual-IMU board (compiled, no allocation).

The single-IMU filter (:mod:`footnav.pipeline.navigation.eskf`) hand-unrolls its sparse blocks for speed; the dual-IMU
filters (12 and 21 states) are small enough that plain dense loops cost a few microseconds a sample.

- :func:`propagate` — ``P ← F P Fᵀ + diag(q)``, over the structural non-zeros of ``F`` (:func:`pattern`).
- :func:`update3` — one 3-row measurement ``y = H δx + n``, ``n ~ N(0, diag(r))``: gain
  ``K = P Hᵀ S⁻¹``, ``δx = K y`` and the Joseph-form covariance written out for any gain,
  ``(I − KH) P (I − KH)ᵀ + K R Kᵀ = P − K H P − P Hᵀ Kᵀ + K S Kᵀ`` (Bucy & Joseph 1968; it stays
  symmetric positive semi-definite where the short form ``(I − KH) P`` drifts). Returns the
  normalised innovation squared ``yᵀ S⁻¹ y`` (χ² with 3 degrees of freedom when the model holds).

References
----------
- Bucy, R. S. and Joseph, P. D. (1968). *Filtering for Stochastic Processes with Applications to
  Guidance*. Interscience (the Joseph form).
- Bar-Shalom, Li and Kirubarajan (2001). *Estimation with Applications to Tracking and Navigation*,
  Wiley, §5.4 (NIS and its χ² test).
"""

from __future__ import annotations

import numpy as np
from footnav.pipeline.jit import njit
from footnav.pipeline.navigation.eskf import _inv3_spd
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@njit(cache=True, nogil=True)
def pattern(F: F64) -> tuple[NDArray[np.int64], NDArray[np.int64]]:  # pragma: no cover - compiled
    """Row pointers and column indices (CSR) of the entries of ``F`` that are not zero."""
    n = F.shape[0]
    ptr = np.zeros(n + 1, dtype=np.int64)
    idx = np.empty(n * n, dtype=np.int64)
    k = 0
    for i in range(n):
        for j in range(n):
            if F[i, j] != 0.0:
                idx[k] = j
                k += 1
        ptr[i + 1] = k
    return ptr, idx[:k]


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def propagate(P: F64, F: F64, ptr: NDArray[np.int64], idx: NDArray[np.int64], q_diag: F64, M: F64) -> None:
    """``P ← F P Fᵀ + diag(q_diag)`` in place, visiting only ``F``'s structural non-zeros.

    ``ptr``, ``idx``: the pattern of ``F`` (:func:`pattern`, taken once with every block that can be
    non-zero set); ``M`` is (n, n) scratch. Writes the upper triangle and mirrors it.
    """  # pragma: no cover
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            s = 0.0
            for t in range(ptr[i], ptr[i + 1]):
                s += F[i, idx[t]] * P[idx[t], j]
            M[i, j] = s
    for i in range(n):
        for j in range(i, n):
            s = 0.0
            for t in range(ptr[j], ptr[j + 1]):
                s += M[i, idx[t]] * F[j, idx[t]]
            P[i, j] = s
    for i in range(n):
        P[i, i] += q_diag[i]
        for j in range(i):
            P[i, j] = P[j, i]


@njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"})
def update3(
    dx: F64, P: F64, H: F64, y: F64, r: F64, work: F64, gate: float = np.inf, r_gate: F64 | None = None
) -> float:
    """One 3-row update (module docstring); adds ``K y`` to ``dx`` (n,), updates ``P`` (n, n).

    ``H`` is (3, n), ``y`` (3,), ``r`` (3,) the noise variances, ``work`` (9, n) scratch. Returns the NIS;
    when it is ``gate`` or more the update is not applied (a χ² gate). With ``r_gate`` (3,) the gate's
    NIS uses those variances instead of ``r`` (the zero-angular-rate gate of ``footnav.pipeline.navigation.eskf``:
    tested
    against the sensor noise, weighted with more), and that NIS is returned.
    """  # pragma: no cover
    n = P.shape[0]
    # rows 0-2 of work: (P Hᵀ)ᵀ = H P (P symmetric)
    for a in range(3):
        for j in range(n):
            s = 0.0
            for k in range(n):
                h = H[a, k]
                if h != 0.0:
                    s += h * P[k, j]
            work[a, j] = s
    S = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            s = 0.0
            for k in range(n):
                h = H[b, k]
                if h != 0.0:
                    s += work[a, k] * h
            S[a, b] = s
        S[a, a] += r[a]
    i00, i01, i02, i11, i12, i22 = _inv3_spd(
        S[0, 0], 0.5 * (S[0, 1] + S[1, 0]), 0.5 * (S[0, 2] + S[2, 0]), S[1, 1], 0.5 * (S[1, 2] + S[2, 1]), S[2, 2]
    )
    if r_gate is None:
        nis = (
            y[0] * (i00 * y[0] + i01 * y[1] + i02 * y[2])
            + y[1] * (i01 * y[0] + i11 * y[1] + i12 * y[2])
            + y[2] * (i02 * y[0] + i12 * y[1] + i22 * y[2])
        )
    else:
        g00, g01, g02, g11, g12, g22 = _inv3_spd(
            S[0, 0] - r[0] + r_gate[0],
            0.5 * (S[0, 1] + S[1, 0]),
            0.5 * (S[0, 2] + S[2, 0]),
            S[1, 1] - r[1] + r_gate[1],
            0.5 * (S[1, 2] + S[2, 1]),
            S[2, 2] - r[2] + r_gate[2],
        )
        nis = (
            y[0] * (g00 * y[0] + g01 * y[1] + g02 * y[2])
            + y[1] * (g01 * y[0] + g11 * y[1] + g12 * y[2])
            + y[2] * (g02 * y[0] + g12 * y[1] + g22 * y[2])
        )
    if not nis < gate:
        return nis
    # rows 3-5: Kᵀ = S⁻¹ H P; rows 6-8: D = (K S)ᵀ − H P, so that the Joseph form is
    # P_ij + Σ_a (D_ai K_ja − K_ia (HP)_aj) (the same expansion as footnav.pipeline.navigation.eskf._update3)
    for j in range(n):
        h0, h1, h2 = work[0, j], work[1, j], work[2, j]
        k0 = i00 * h0 + i01 * h1 + i02 * h2
        k1 = i01 * h0 + i11 * h1 + i12 * h2
        k2 = i02 * h0 + i12 * h1 + i22 * h2
        work[3, j], work[4, j], work[5, j] = k0, k1, k2
        work[6, j] = k0 * S[0, 0] + k1 * S[1, 0] + k2 * S[2, 0] - h0
        work[7, j] = k0 * S[0, 1] + k1 * S[1, 1] + k2 * S[2, 1] - h1
        work[8, j] = k0 * S[0, 2] + k1 * S[1, 2] + k2 * S[2, 2] - h2
        dx[j] += k0 * y[0] + k1 * y[1] + k2 * y[2]
    for i in range(n):
        for j in range(i, n):
            acc = P[i, j]
            for a in range(3):
                acc += work[6 + a, i] * work[3 + a, j] - work[3 + a, i] * work[a, j]
            P[i, j] = acc
    for i in range(n):
        for j in range(i):
            P[i, j] = P[j, i]
    return nis
