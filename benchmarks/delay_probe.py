"""Probe: does an accelerometer-gyroscope delay explain the vertical drift? (issue 4)

    .venv/bin/python -m benchmarks.delay_probe [--data ../shared/data] [--sigma-ms 5] [--no-emulator]

The filter of ``benchmarks.numpy_filter`` (the plain reference of ``pipeline.eskf``) with one more
error state: a constant delay τ of the gyroscope behind the accelerometer, ω_m(t) = ω(t − τ) + b_g,
as in online temporal calibration (Li and Mourikis, "Online temporal calibration for camera-IMU
systems", IJRR 2014; per-sensor and per-axis offsets: Rehder et al., "Extending kalibr: calibrating
the extrinsics of multiple IMUs and of individual axes", ICRA 2016). To first order the true rate is
ω(t) = ω_m(t + τ) − b_g ≈ ω_m − b_g + τ ω̇_m, with ω̇_m the backward difference of the gyroscope
samples (causal; summed over an interval it telescopes to τ Δω_m, so the attitude it adds is exact to
first order whatever the difference scheme). The nominal rate uses τ̂, and with the global attitude
error of ``pipeline.eskf`` (Solà 2017, §7.2.1) the error model gains one column:

    δθ' = −R δb_g + R ω̇_m δτ,     δτ' = 0 (random constant, prior σ_τ)

Zero-velocity updates observe τ through the velocity error a delay leaves at the end of each swing.

It runs every recording of ``benchmarks.accuracy`` through the unchanged navigator (alignment,
detector, saturation repair) with this filter in place of ``eskf.run_filter`` (``unittest.mock``,
for this probe only), and prints τ̂ and its σ at the end of each recording beside the accuracy
figures, then the emulated walks with and without an injected delay (``corrupt(gyr_delay_s=...)``).

What it showed (2026-11-22, ``--sigma-ms 5``): on the emulator an injected 5 ms delay is recovered
(5.1-5.2 ± 0.2 ms) and its vertical error removed, but the real recordings do not behave like a
constant delay: τ̂ stays near 0 on the x-io and OpenShoe loops (whose height drift a fixed shift of
+5 / −6 ms would remove, at the price of a 0.05 m/s vertical velocity error at every heel strike), and
on the nine PyShoe trials of one unit it scatters from −7 to +6 ms, mostly with σ below 1 ms. The state was
therefore not added to ``pipeline.eskf``; see README, "Accuracy".
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

import numpy as np
from numpy.typing import NDArray

from app.evaluate import evaluate_file, find_recordings
from benchmarks.numpy_filter import quat_exp, quat_mul, quat_to_mat, skew
from device.emulator.gait import simulate_walk
from device.emulator.imu_errors import corrupt
from pipeline import eskf
from pipeline.navigator import NavConfig, navigate
from pipeline.profiles import get_profile

F64 = NDArray[np.float64]

N_AUG = eskf.N_STATE + 1
TAU = eskf.N_STATE  # index of δτ in the augmented error state
_I3 = np.eye(3)
_I = np.eye(N_AUG)
DEFAULT_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@dataclass(frozen=True, slots=True)
class DelayRun:
    """Outputs of :func:`run_filter_delay`: those of ``numpy_filter.FilterRun`` plus τ̂.

    Attributes:
        pos_n_m, vel_n_mps: (n, 3); quat_nb_wxyz: (n, 4); pos_cov_n_m2: (n, 4, 4) of (x, y, z, ψ).
        counters: (eskf.N_CNT,) as ``eskf.run_filter``'s.
        x: final nominal state (16,); P: final error covariance (16, 16), τ last.
        tau_s: (n,) the delay estimate after each sample, s.
    """

    pos_n_m: F64
    vel_n_mps: F64
    quat_nb_wxyz: F64
    pos_cov_n_m2: F64
    counters: NDArray[np.int64]
    x: F64
    P: F64
    tau_s: F64


def _update(x: F64, tau: float, P: F64, H: F64, y: F64, R: F64) -> tuple[F64, float, F64]:
    """Joseph-form update, injection (τ included) and reset, as ``numpy_filter._update``."""
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T
    I_KH = _I - K @ H
    P = I_KH @ P @ I_KH.T + K @ R @ K.T
    dx = K @ y
    x = x.copy()
    x[0:6] += dx[0:6]
    x[10:16] += dx[9:15]
    q = quat_mul(quat_exp(dx[6:9]), x[6:10])
    x[6:10] = q / np.linalg.norm(q)
    G = _I.copy()
    G[6:9, 6:9] += skew(0.5 * dx[6:9])
    P = G @ P @ G.T
    return x, tau + float(dx[TAU]), 0.5 * (P + P.T)


def run_filter_delay(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    par: F64,
    sigma_tau_s: float,
    tau0_s: float = 0.0,
) -> DelayRun:
    """``numpy_filter.run_filter_numpy`` with the delay state (module docstring); ``P`` is the
    (15, 15) covariance of the other states, τ starts at ``tau0_s`` with 1σ ``sigma_tau_s``
    (0: a known, fixed delay)."""
    n = acc_b_mps2.shape[0]
    x = x.astype(np.float64).copy()
    P_aug = np.zeros((N_AUG, N_AUG))
    P_aug[:TAU, :TAU] = P
    P_aug[TAU, TAU] = sigma_tau_s**2
    P = P_aug
    tau = tau0_s
    g = par[eskf.PAR_G]
    g_n = np.array([0.0, 0.0, g])
    counters = np.zeros(eskf.N_CNT, dtype=np.int64)
    H_v, H_bg = _I[3:6], _I[12:15]
    R_zaru = par[eskf.PAR_ZARU] ** 2 * _I3
    pos, vel = np.empty((n, 3)), np.empty((n, 3))
    quat, pos_cov, taus = np.empty((n, 4)), np.empty((n, 4, 4)), np.empty(n)
    previous: F64 | None = None
    for k in range(n):
        dt = float(dt_s[k])
        bad = not (np.isfinite(acc_b_mps2[k]).all() and np.isfinite(gyr_b_radps[k]).all())
        counters[eskf.CNT_BAD_SAMPLE] += bad
        if not (dt > 0.0 and math.isfinite(dt)):
            counters[eskf.CNT_BAD_DT] += 1
        else:
            counters[eskf.CNT_GAP] += dt >= par[eskf.PAR_DT_MAX]
            R = quat_to_mat(x[6:10])
            f2 = w2 = 0.0
            w_dot = np.zeros(3)
            if bad:
                f_n = g_n.copy()
            else:
                if previous is not None:
                    w_dot = (gyr_b_radps[k] - previous) / dt
                previous = gyr_b_radps[k].copy()
                omega = gyr_b_radps[k] - x[13:16] + tau * w_dot
                f_b = acc_b_mps2[k] - x[10:13]
                f2, w2 = float(f_b @ f_b), float(omega @ omega)
                q = quat_mul(x[6:10], quat_exp(omega * dt))
                x[6:10] = q / np.linalg.norm(q)
                R_new = quat_to_mat(x[6:10])
                f_n = 0.5 * (R + R_new) @ f_b
                R = R_new
            a = f_n - g_n
            x[0:3] += x[3:6] * dt + 0.5 * a * dt * dt
            x[3:6] += a * dt
            F = _I.copy()
            F[0:3, 3:6] = dt * _I3
            F[3:6, 6:9] = -dt * skew(f_n)
            F[3:6, 9:12] = -dt * R
            F[6:9, 12:15] = -dt * R
            F[6:9, TAU] = dt * R @ w_dot
            q_diag = np.zeros(N_AUG)
            q_diag[3:6] = (par[eskf.PAR_SIG_ACC] ** 2 + par[eskf.PAR_ACC_SCALE] ** 2 * f2) * dt * dt
            q_diag[6:9] = (par[eskf.PAR_SIG_GYR] ** 2 + par[eskf.PAR_GYR_SCALE] ** 2 * w2) * dt * dt
            q_diag[9:12] = par[eskf.PAR_BA_RW] ** 2 * dt
            q_diag[12:15] = par[eskf.PAR_BG_RW] ** 2 * dt
            P = F @ P @ F.T + np.diag(q_diag)
            P = 0.5 * (P + P.T)
        if stance[k] and not bad:
            omega = gyr_b_radps[k] - x[13:16]
            r_zupt = par[eskf.PAR_ZUPT] ** 2 + par[eskf.PAR_ROLL_LEVER] ** 2 * float(omega @ omega)
            x, tau, P = _update(x, tau, P, H_v, -x[3:6], r_zupt * _I3)
            counters[eskf.CNT_UPDATES] += 1
            y = gyr_b_radps[k] - x[13:16]
            S = H_bg @ P @ H_bg.T + R_zaru
            if float(y @ np.linalg.solve(S, y)) < par[eskf.PAR_ZARU_GATE]:
                x, tau, P = _update(x, tau, P, H_bg, y, R_zaru)
                counters[eskf.CNT_ZARU] += 1
            else:
                counters[eskf.CNT_ZARU_REJECTED] += 1
        pos[k], vel[k], quat[k] = x[0:3], x[3:6], x[6:10]
        pos_cov[k] = P[np.ix_([0, 1, 2, 8], [0, 1, 2, 8])]
        taus[k] = tau
    return DelayRun(pos, vel, quat, pos_cov, counters, x, P, taus)


@contextmanager
def delay_filter_in_navigator(sigma_tau_s: float, tau0_s: float = 0.0) -> Iterator[list[DelayRun]]:
    """Within the block, the navigator runs :func:`run_filter_delay` instead of ``eskf.run_filter``
    (one call per navigated batch); the runs are appended to the list it yields."""
    runs: list[DelayRun] = []

    def run_filter(
        x: F64,
        P: F64,
        acc: F64,
        gyr: F64,
        dt: F64,
        stance: NDArray[np.bool_],
        zupt_ratio: F64,  # not used: this probe keeps the ZUPT noise equal on all axes, as measured
        par: F64,
        out_pos: F64,
        out_vel: F64,
        out_quat: F64,
        out_cov: F64,
        counters: NDArray[np.int64],
    ) -> None:
        r = run_filter_delay(x, P, acc, gyr, dt, stance, par, sigma_tau_s, runs[-1].tau_s[-1] if runs else tau0_s)
        n = acc.shape[0]
        x[:] = r.x
        P[:] = r.P[:TAU, :TAU]
        out_pos[:n], out_vel[:n], out_quat[:n], out_cov[:n] = r.pos_n_m, r.vel_n_mps, r.quat_nb_wxyz, r.pos_cov_n_m2
        counters += r.counters
        runs.append(r)

    with mock.patch.object(eskf, "run_filter", run_filter):
        yield runs


def emulated(path: str, duration_s: float, seed: int, delay_s: float, sigma_tau_s: float) -> str:
    """One emulated walk with an injected delay, through the plain filter and the delay filter."""
    truth = simulate_walk(path, duration_s, rate_hz=1000.0, seed=0)
    acc, gyr, _ = corrupt(
        truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=seed, gyr_delay_s=delay_s
    )
    cfg = NavConfig(profile=get_profile("mpu6500x4"))
    cells = []
    tau = ""
    for with_tau in (False, True):
        if with_tau:
            with delay_filter_in_navigator(sigma_tau_s) as runs:
                nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, cfg)
            tau = f"τ̂ {1e3 * runs[-1].tau_s[-1]:+.2f} ± {1e3 * math.sqrt(runs[-1].P[TAU, TAU]):.2f} ms"
        else:
            nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, cfg)
        assert nav is not None
        err = nav.pos_n_m - truth.pos_n_m[-len(nav) :]
        pct = 100.0 * float(np.linalg.norm(err[-1])) / truth.distance_m
        cells.append(f"{pct:.3f} % dz {err[-1, 2]:+.3f} m")
    head = f"emulated {path:<9} {duration_s:3.0f} s, delay {1e3 * delay_s:+.1f} ms"
    return f"{head}: plain {cells[0]};  with τ {cells[1]}, {tau}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--sigma-ms", type=float, default=5.0, help="prior 1σ of the delay, ms")
    ap.add_argument("--no-emulator", action="store_true")
    args = ap.parse_args(argv)
    sigma = 1e-3 * args.sigma_ms
    t0 = time.perf_counter()
    for f in find_recordings([args.data]) if args.data.exists() else []:
        with delay_filter_in_navigator(sigma) as runs:
            e = evaluate_file(f)
        figures = (
            f"ARMSE-2D {e.armse_2d_m:.3f} ATE-3D {e.ate_3d_m:.3f}"
            if not math.isnan(e.armse_2d_m)
            else f"loop 3D {e.loop_3d_m:.3f} 2D {e.loop_2d_m:.3f}"
        )
        tau, sd = runs[-1].tau_s[-1], math.sqrt(runs[-1].P[TAU, TAU])
        print(f"{e.name[:22]:<22} {e.format:<8} {figures}  τ̂ {1e3 * tau:+.2f} ± {1e3 * sd:.2f} ms", flush=True)
    if not args.no_emulator:
        for path, dur, seed in (("rectangle", 60.0, 7), ("stairs", 60.0, 1)):
            for delay in (0.0, 0.005):
                print(emulated(path, dur, seed, delay, sigma), flush=True)
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
