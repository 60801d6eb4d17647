"""Zero-velocity update noise and stance onset: the variants measured for issue 4, on every recording.

    .venv/bin/python -m benchmarks.zupt_noise [--variants NAME ...] [--seeds 8] [--no-nees] [--data ../shared/data]

Each variant runs the whole navigator (detector, alignment, saturation repair) with
:func:`run_filter_variant` in place of ``eskf.run_filter`` (``unittest.mock``, for this probe only).
That filter is ``eskf.run_filter`` with the ZUPT noise written out per axis of the navigation
frame: σ² = σ_zupt² + (r |ω|)² + e_k[axis], where e_k (n, 3) is the variant's extra variance at
sample k; a variant may also drop ZUPTs (``skip``). The hard ZUPT (e = 0) is the filter before
issue 4's change; ``stat-z 0.2`` (e_z = 0.2² · T/γ, the detector's
statistic over its threshold) is the present default and reproduces ``eskf.run_filter``.

Variants (``VARIANTS``), all one configuration for every recording:

- ``hard``: e = 0;
- ``stat`` / ``stat-z``: e = σ_T² (T/γ)^p on all axes / on the vertical only;
- ``acc`` / ``acc-z``: e = (τ | |f| − g |)², the velocity a specific-force deviation builds in τ;
- ``onset`` / ``onset-z``: e = σ² exp(−t/τ), t the time since the stance run began;
- ``skip k``: no ZUPT on the first k samples of a stance;
- ``det …``: the hard ZUPT with one detector setting changed (window, debounce, hysteresis, margin).

Reported per variant: PyShoe ARMSE-2D mean / median / max and ATE-3D mean, the per-trial ARMSE, the
x-io and OpenShoe loops 3D / 2D, the emulated walks of ``benchmarks.accuracy`` (end error % of
distance, mean position NEES), optionally 2 × ``--seeds`` seeded 240 s walks at 1 kHz, and the
PyShoe NEES (the 2D and vertical position error after the yaw + translation fit of
``pipeline.metrics.ate``, over the filter's own covariance, mean over each trial from its second
second; a rough consistency figure, since the fit itself removes part of the error).

What it showed (README "Accuracy"): only a soft *vertical* update helps the recordings as a whole;
anything that weakens or drops the horizontal update at stance onset costs the PyShoe trials (most
of all the running one, whose stances are short), and the detector's window, debounce and
hysteresis are where the existing defaults put them. Among the vertical forms, T/γ lowers the 3D
errors of all three kinds of recording together; the specific-force and time-since-onset forms help
x-io and not OpenShoe.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np
from numba import njit
from numpy.typing import NDArray

import app.export
import benchmarks.accuracy
from benchmarks.accuracy import DEFAULT_DATA, EMULATED, emulated_row, real_rows
from device.emulator.gait import simulate_walk
from device.emulator.imu_errors import corrupt
from pipeline import eskf, navigator
from pipeline.eskf import (
    _POS_YAW,
    BG0,
    CNT_BAD_DT,
    CNT_BAD_SAMPLE,
    CNT_GAP,
    CNT_UPDATES,
    CNT_ZARU,
    CNT_ZARU_REJECTED,
    N_STATE,
    PAR_DT_MAX,
    PAR_G,
    PAR_ROLL_LEVER,
    PAR_ZARU,
    PAR_ZARU_GATE,
    PAR_ZUPT,
    V0,
    _nis3,
    _process_noise,
    _propagate_cov,
    _update3,
    _update3_diag,
)
from pipeline.loaders import load_recording
from pipeline.metrics import ate
from pipeline.navigator import NavConfig, navigate
from pipeline.profiles import get_profile
from pipeline.quaternion import quat_from_rotvec_s, quat_mul_s, quat_to_mat_into

F64 = NDArray[np.float64]

VARIANTS: dict[str, dict[str, Any]] = {
    "hard": {},
    "stat 0.02": {"kind": "stat", "sig": 0.02},
    "stat 0.05": {"kind": "stat", "sig": 0.05},
    "stat 0.1": {"kind": "stat", "sig": 0.1},
    "stat-z 0.05": {"kind": "stat", "sig": 0.05, "vert": True},
    "stat-z 0.1": {"kind": "stat", "sig": 0.1, "vert": True},
    "stat-z 0.15": {"kind": "stat", "sig": 0.15, "vert": True},
    "stat-z 0.2": {"kind": "stat", "sig": 0.2, "vert": True},
    "stat-z 0.3": {"kind": "stat", "sig": 0.3, "vert": True},
    "stat-z 0.4": {"kind": "stat", "sig": 0.4, "vert": True},
    "stat-z 0.1 p0.5": {"kind": "stat", "sig": 0.1, "vert": True, "pow": 0.5},
    "stat-z 0.2 p2": {"kind": "stat", "sig": 0.2, "vert": True, "pow": 2.0},
    "stat-z 0.3 p2": {"kind": "stat", "sig": 0.3, "vert": True, "pow": 2.0},
    "acc 10ms": {"kind": "acc", "tau": 0.01},
    "acc 30ms": {"kind": "acc", "tau": 0.03},
    "acc-z 30ms": {"kind": "acc", "tau": 0.03, "vert": True},
    "acc-z 50ms": {"kind": "acc", "tau": 0.05, "vert": True},
    "acc-z 100ms": {"kind": "acc", "tau": 0.1, "vert": True},
    "onset 0.05/20ms": {"kind": "onset", "sig": 0.05, "tau": 0.02},
    "onset-z 0.05/20ms": {"kind": "onset", "sig": 0.05, "tau": 0.02, "vert": True},
    "onset-z 0.2/20ms": {"kind": "onset", "sig": 0.2, "tau": 0.02, "vert": True},
    "skip 1": {"kind": "skip", "k": 1},
    "skip 2": {"kind": "skip", "k": 2},
    "det window 20ms": {"det": {"window_s": 0.02}},
    "det window 30ms": {"det": {"window_s": 0.03}},
    "det min_stance 10ms": {"det": {"min_stance_s": 0.01}},
    "det min_stance 30ms": {"det": {"min_stance_s": 0.03}},
    "det hysteresis 0.2": {"det": {"stance_hysteresis_decades": 0.2}},
}
DEFAULT_VARIANTS = ("hard", "stat-z 0.1", "stat-z 0.2", "stat-z 0.3")


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def run_filter_variant(
    x: F64,
    P: F64,
    acc_b_mps2: F64,
    gyr_b_radps: F64,
    dt_s: F64,
    stance: NDArray[np.bool_],
    par: F64,
    out_pos: F64,
    out_vel: F64,
    out_quat: F64,
    out_cov: F64,
    counters: NDArray[np.int64],
    extra: F64,
    skip: NDArray[np.bool_],
) -> None:  # pragma: no cover - compiled
    """``eskf.run_filter`` with the ZUPT noise of each axis grown by ``extra`` (n, 3) and no ZUPT
    (nor ZARU) at samples where ``skip`` (n,) is set (module docstring)."""
    n = acc_b_mps2.shape[0]
    g = par[PAR_G]
    q_diag = np.zeros(N_STATE)
    r_zaru = par[PAR_ZARU] ** 2
    y = np.empty(3)
    f_n = np.empty(3)
    R0 = np.empty((3, 3))
    R1 = np.empty((3, 3))
    M = np.empty((9, N_STATE))
    work = np.empty((10, N_STATE))
    for k in range(n):
        dt = dt_s[k]
        bad = False
        for r in range(3):
            if not (math.isfinite(acc_b_mps2[k, r]) and math.isfinite(gyr_b_radps[k, r])):
                bad = True
        if bad:
            counters[CNT_BAD_SAMPLE] += 1
        if dt <= 0.0 or not math.isfinite(dt):
            counters[CNT_BAD_DT] += 1
        else:
            if dt >= par[PAR_DT_MAX]:
                counters[CNT_GAP] += 1
            quat_to_mat_into(x[6], x[7], x[8], x[9], R0)
            if bad:
                f_n[0], f_n[1], f_n[2] = 0.0, 0.0, g
            else:
                w0 = gyr_b_radps[k, 0] - x[13]
                w1 = gyr_b_radps[k, 1] - x[14]
                w2 = gyr_b_radps[k, 2] - x[15]
                fb0 = acc_b_mps2[k, 0] - x[10]
                fb1 = acc_b_mps2[k, 1] - x[11]
                fb2 = acc_b_mps2[k, 2] - x[12]
                ew, ex, ey, ez = quat_from_rotvec_s(w0 * dt, w1 * dt, w2 * dt)
                qw, qx, qy, qz = quat_mul_s(x[6], x[7], x[8], x[9], ew, ex, ey, ez)
                norm = math.sqrt(qw**2 + qx**2 + qy**2 + qz**2)
                qw, qx, qy, qz = qw / norm, qx / norm, qy / norm, qz / norm
                x[6], x[7], x[8], x[9] = qw, qx, qy, qz
                quat_to_mat_into(qw, qx, qy, qz, R1)
                for r in range(3):
                    f_n[r] = (
                        0.0
                        + 0.5 * (R0[r, 0] + R1[r, 0]) * fb0
                        + 0.5 * (R0[r, 1] + R1[r, 1]) * fb1
                        + 0.5 * (R0[r, 2] + R1[r, 2]) * fb2
                    )
                for r in range(3):
                    for c in range(3):
                        R0[r, c] = R1[r, c]
            for r in range(3):
                a = f_n[r] - (g if r == 2 else 0.0)
                x[r] += x[3 + r] * dt + 0.5 * a * dt * dt
                x[3 + r] += a * dt
            if bad:
                f2, w2 = 0.0, 0.0
            else:
                f2 = fb0 * fb0 + fb1 * fb1 + fb2 * fb2
                w2 = w0 * w0 + w1 * w1 + w2 * w2
            _process_noise(par, f2, w2, dt, q_diag)
            _propagate_cov(P, M, R0, f_n, dt, q_diag)
        if stance[k] and not bad and not skip[k]:
            w2 = 0.0
            for r in range(3):
                y[r] = -x[3 + r]
                w2 += (gyr_b_radps[k, r] - x[13 + r]) ** 2
            rb = par[PAR_ZUPT] ** 2 + par[PAR_ROLL_LEVER] ** 2 * w2
            _update3_diag(x, P, V0, y, rb + extra[k, 0], rb + extra[k, 1], rb + extra[k, 2], work)
            counters[CNT_UPDATES] += 1
            for r in range(3):
                y[r] = gyr_b_radps[k, r] - x[13 + r]
            if _nis3(P, BG0, y[0], y[1], y[2], r_zaru) < par[PAR_ZARU_GATE]:
                _update3(x, P, BG0, y, r_zaru, work)
                counters[CNT_ZARU] += 1
            else:
                counters[CNT_ZARU_REJECTED] += 1
        for r in range(3):
            out_pos[k, r] = x[r]
            out_vel[k, r] = x[3 + r]
        for r in range(4):
            for c in range(4):
                out_cov[k, r, c] = P[_POS_YAW[r], _POS_YAW[c]]
        for r in range(4):
            out_quat[k, r] = x[6 + r]


def extra_variance(
    v: dict[str, Any], acc: F64, stance: NDArray[np.bool_], ratio: F64, dt: F64, g: float
) -> tuple[F64, NDArray[np.bool_]]:
    """The extra ZUPT variance (n, 3) and the skipped samples (n,) of variant ``v`` for one batch."""
    n = stance.shape[0]
    ex = np.zeros((n, 3))
    skip = np.zeros(n, np.bool_)
    idx = np.arange(n)
    since = idx - np.maximum.accumulate(np.where(~stance, idx, -1))  # samples since the stance began
    kind = v.get("kind")
    val = np.zeros(n)
    if kind == "stat":
        val = v["sig"] ** 2 * ratio ** v.get("pow", 1.0)
    elif kind == "acc":
        val = (v["tau"] * np.abs(np.linalg.norm(acc, axis=1) - g)) ** 2
    elif kind == "onset":
        val = v["sig"] ** 2 * np.exp(-since * float(np.nanmedian(dt)) / v["tau"])
    elif kind == "skip":
        skip = since <= v["k"]
    val = np.where(np.isfinite(val), val, 1e6)
    for a in [2] if v.get("vert") else [0, 1, 2]:
        ex[:, a] = val
    return np.ascontiguousarray(ex), skip


@contextlib.contextmanager
def variant_in_navigator(v: dict[str, Any]) -> Iterator[None]:
    """Within the block, the navigator (``navigate``, ``navigate_recording``) runs variant ``v``."""

    def run(
        x: F64,
        P: F64,
        acc: F64,
        gyr: F64,
        dt: F64,
        stance: NDArray[np.bool_],
        zupt_ratio: F64,
        par: F64,
        pos: F64,
        vel: F64,
        quat: F64,
        cov: F64,
        counters: NDArray[np.int64],
    ) -> None:
        ex, skip = extra_variance(v, acc, stance, zupt_ratio, dt, float(par[PAR_G]))
        run_filter_variant(x, P, acc, gyr, dt, stance, par, pos, vel, quat, cov, counters, ex, skip)

    patches: list[Any] = [mock.patch.object(eskf, "run_filter", run)]
    if "det" in v:
        base = navigator.NavConfig

        def config(*args: Any, **kw: Any) -> NavConfig:
            c = base(*args, **kw)
            return dataclasses.replace(c, detector=dataclasses.replace(c.detector, **v["det"]))

        patches += [mock.patch.object(app.export, "NavConfig", config)]
        patches += [mock.patch.object(benchmarks.accuracy, "NavConfig", config)]
    with contextlib.ExitStack() as stack:
        for p in patches:
            stack.enter_context(p)
        yield


def pyshoe_nees(data: Path) -> F64:
    """(trials, 2): mean 2D and vertical position NEES of each PyShoe trial (module docstring)."""
    out = []
    for f in sorted((data / "pyshoe-vicon").glob("*.mat")):
        rec = load_recording(f)
        assert rec.gt_pos_m is not None
        nav, st = app.export.navigate_recording(rec)
        sk = st.samples_before_alignment
        gt = rec.gt_pos_m[sk:] - rec.gt_pos_m[sk]
        est, cov = nav.pos_n_m.copy(), nav.pos_cov_n_m2.copy()
        fit = ate(est, gt, mirror_test=True)
        if fit.mirrored:
            est[:, 1] *= -1
            cov[:, 1, :] *= -1
            cov[:, :, 1] *= -1
        c, s = math.cos(fit.yaw_rad), math.sin(fit.yaw_rad)
        rot = np.array([[c, -s], [s, c]])
        e2 = (est[:, :2] - est[:, :2].mean(0)) @ rot.T + gt[:, :2].mean(0) - gt[:, :2]
        ez = est[:, 2] - est[:, 2].mean() + gt[:, 2].mean() - gt[:, 2]
        c2 = np.einsum("ij,njk,lk->nil", rot, cov[:, :2, :2], rot)
        k0 = round(rec.rate_hz)
        n2 = np.einsum("ni,nij,nj->n", e2[k0:], np.linalg.inv(c2[k0:]), e2[k0:]).mean()
        out.append((n2, float(np.mean(ez[k0:] ** 2 / cov[k0:, 2, 2]))))
    return np.array(out)


def seeded_walks(seeds: int) -> F64:
    """(2 · seeds,): end error % of distance of the rectangle and figure-eight, 240 s at 1 kHz."""
    rows = []
    for path in ("rectangle", "figure8"):
        truth = simulate_walk(path, 240.0, rate_hz=1000.0, seed=0)
        for seed in range(1, seeds + 1):
            acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=seed)
            nav, _ = navigate(truth.t_s, acc, gyr, truth.rate_hz, NavConfig(profile=get_profile("mpu6500x4")))
            assert nav is not None
            rows.append(100.0 * np.linalg.norm(nav.pos_n_m[-1] - truth.pos_n_m[-1]) / truth.distance_m)
    return np.array(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", nargs="+", default=list(DEFAULT_VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--seeds", type=int, default=0, help="IMU error seeds per seeded emulated walk (0: skip)")
    ap.add_argument("--no-nees", action="store_true", help="skip the PyShoe NEES")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    args = ap.parse_args(argv)
    for name in args.variants:
        t0 = time.perf_counter()
        with variant_in_navigator(VARIANTS[name]):
            rows = real_rows(args.data, smooth=False)
            emus = [emulated_row(*e) for e in EMULATED]
            nees = None if args.no_nees else pyshoe_nees(args.data)
            seeded = seeded_walks(args.seeds) if args.seeds > 0 else None
        py = [r for r in rows if r[1] == "pyshoe"]
        a = np.array([r[2] for r in py])
        ate3 = np.array([r[3] for r in py])
        loops = "  ".join(f"{r[0]} {r[4]:.3f} / {r[5]:.3f}" for r in rows if not math.isnan(r[4]))
        print(f"=== {name}")
        print(f"  PyShoe ARMSE-2D {a.mean():.4f} / {np.median(a):.4f} / {a.max():.4f}, ATE-3D mean {ate3.mean():.4f}")
        print("  per trial " + " ".join(f"{x:.3f}" for x in a))
        print(f"  loops 3D / 2D: {loops}")
        cells = [f"{p:<9} {e[0]:.4f} % NEES {e[2]:.2f}" for (p, _, _), e in zip(EMULATED, emus, strict=True)]
        print("  emulated " + "  ".join(cells))
        if nees is not None:
            print("  PyShoe NEES 2D " + " ".join(f"{v:.1f}" for v in nees[:, 0]))
            print("  PyShoe NEES z  " + " ".join(f"{v:.1f}" for v in nees[:, 1]))
        if seeded is not None:
            print(
                f"  {seeded.size} seeded walks: end error % mean {seeded.mean():.4f} median {np.median(seeded):.4f} "
                f"max {seeded.max():.4f}"
            )
        print(f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
