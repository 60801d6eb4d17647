"""Estimator throughput: detector, filter and both, against a plain numpy per-sample filter.

Replays an emulated walk (``footnav.device.emulator``: 10 minutes at 1 kHz by default, MPU-6500-class sensor
errors) through the estimators the way ``footnav replay`` and ``footnav export`` do, in one big
batch, on one core, and prints a table of samples per second. Each figure is the best of a few
repeats (wall clock; the CPU-time figure beside it is less sensitive to other load on the machine).
The baseline, ``benchmarks.numpy_filter``, is the same filter written plainly with numpy; it runs on
the first ``--baseline-s`` seconds of the same walk, and so does a compiled run for the like-for-like
ratio. Ratios are the figures to compare across machines; absolute rates depend on the CPU.
Numba compile time is measured in fresh interpreters: once with an empty cache, once with the cache
that run wrote.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.pipeline.navigation import eskf
from footnav.pipeline.navigation.alignment import align_from_still
from footnav.pipeline.navigation.batches import NO_CLIPPED_RATES, zupt_ratio
from footnav.pipeline.navigation.navigator import NavConfig, Navigator, filter_start, navigate
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.smoothing.stepwise import StepSmoothingNavigator
from footnav.pipeline.stance.detectors import StreamingDetector

from benchmarks.gaitmap_baseline import gaitmap_wall_s
from benchmarks.machine import machine
from benchmarks.numpy_filter import run_filter_numpy

RATE_HZ = 1000.0
ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True, slots=True)
class Timing:
    """Best-of-repeats timing of one estimator over ``samples`` samples."""

    name: str
    samples: int
    wall_s: float
    cpu_s: float

    @property
    def rate(self) -> float:
        return self.samples / self.wall_s

    @property
    def cpu_rate(self) -> float:
        return self.samples / self.cpu_s


def _time(name: str, samples: int, fn: Callable[[], object], repeats: int) -> Timing:
    wall, cpu = [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return Timing(name, samples, min(wall), min(cpu))


_COMPILE_PROBE = """
import time
t0 = time.perf_counter()
import numpy as np
from footnav.pipeline.navigation.navigator import navigate
t1 = time.perf_counter()
n = 3000
acc = np.tile([0.0, 0.0, 9.80665], (n, 1)) + np.random.default_rng(0).normal(0, 0.01, (n, 3))
navigate(np.arange(n) / 1000.0, acc, np.zeros((n, 3)), 1000.0)
print(t1 - t0, time.perf_counter() - t1)
"""


def compile_times() -> tuple[float, float, float]:
    """(import s, first navigate call with an empty numba cache s, the same with a warm cache s)."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        runs = []
        for _ in range(2):
            out = subprocess.run(
                [sys.executable, "-c", _COMPILE_PROBE], env=env, cwd=ROOT, capture_output=True, text=True, check=True
            )
            runs.append([float(v) for v in out.stdout.split()])
    return runs[1][0], runs[0][1], runs[1][1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="length of the emulated walk (default 10)")
    ap.add_argument("--baseline-s", type=float, default=30.0, help="seconds the numpy baseline runs on (30)")
    ap.add_argument("--repeats", type=int, default=3, help="repeats per figure; the best counts (3)")
    ap.add_argument("--batch", type=int, default=50, help="samples per batch in the streamed row (50)")
    ap.add_argument("--no-compile", action="store_true", help="skip the compile-time measurement")
    ap.add_argument(
        "--gaitmap",
        metavar="PYTHON",
        help="a Python with gaitmap installed: time its RtsKalman on the walk's first --gaitmap-s seconds too",
    )
    ap.add_argument("--gaitmap-s", type=float, default=120.0, help="seconds of walk gaitmap runs on (120)")
    ap.add_argument(
        "--all",
        action="store_true",
        help="then the whole system too: benchmarks.e2e (latency, CPU, hour replay, .rrd, memory), "
        "benchmarks.soak (an hour of two feet, accelerated), benchmarks.accuracy and benchmarks.consistency "
        "(about 12 minutes)",
    )
    args = ap.parse_args(argv)
    if args.all:
        code = main([a for a in (argv if argv is not None else sys.argv[1:]) if a != "--all"])
        from benchmarks import accuracy, consistency, e2e, soak

        for name, run in (
            ("e2e", e2e.main),
            ("soak", soak.main),
            ("accuracy", accuracy.main),
            ("consistency", consistency.main),
        ):
            print(f"\n{'=' * 30} benchmarks.{name} {'=' * 30}\n", flush=True)
            code |= run([])
        return code

    print("footnav estimator benchmark\n")
    for key, value in machine():
        print(f"  {key:22s} {value}")
    print()

    truth = simulate_walk("rectangle", args.minutes * 60.0, RATE_HZ, seed=1)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, RATE_HZ, "mpu6500x4", seed=2)
    t, n = truth.t_s, len(truth)
    cfg = NavConfig()
    print(f"  input: emulated rectangle walk, {args.minutes:g} min at {RATE_HZ:g} Hz = {n} samples, mpu6500x4 errors")

    # warm up (and compile, if the cache is cold) on a short piece
    navigate(t[:5000], acc[:5000], gyr[:5000], RATE_HZ, cfg)

    # the filter's own inputs: aligned start, the detector's stance flags, the profile's parameters
    stat, threshold, stance = StreamingDetector(cfg.detector, RATE_HZ).update(acc, gyr)
    ratio = zupt_ratio(stat, threshold)
    x0, P0, par = filter_start(cfg, RATE_HZ, align_from_still(acc[:500], gyr[:500]))
    dt = np.diff(t, prepend=t[0] - 1.0 / RATE_HZ)

    def filter_run(m: int) -> tuple[np.ndarray, ...]:
        pos, vel, quat, cov = np.empty((m, 3)), np.empty((m, 3)), np.empty((m, 4)), np.empty((m, 4, 4))
        x, P = x0.copy(), P0.copy()
        eskf.run_filter(
            x, P, acc[:m], gyr[:m], NO_CLIPPED_RATES, dt[:m], stance[:m], ratio[:m], par, pos, vel, quat, cov,
            np.zeros(eskf.N_CNT, dtype=np.int64),
        )  # fmt: skip
        return pos, vel, quat, cov

    def streamed(navigator: type[Navigator] = Navigator) -> None:
        nav = navigator(cfg, RATE_HZ)
        counter, host = np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        for a in range(0, n, args.batch):
            b = a + args.batch
            nav.process(ImuBatch(t[a:b], acc[a:b], gyr[a:b], counter[a:b], host[a:b]))

    r = args.repeats
    rows = [
        _time(
            "detector (SHOE, adaptive threshold)",
            n,
            lambda: StreamingDetector(cfg.detector, RATE_HZ).update(acc, gyr),
            r,
        ),
        _time("filter (15-state ESKF, ZUPT + ZARU)", n, lambda: filter_run(n), r),
        _time("detector + filter (navigate, one batch)", n, lambda: navigate(t, acc, gyr, RATE_HZ, cfg), r),
        _time(f"detector + filter (Navigator, {args.batch}-sample batches)", n, streamed, r),
        _time(
            f"+ step smoothing (live sessions, {args.batch}-sample batches)",
            n,
            lambda: streamed(StepSmoothingNavigator),
            r,
        ),
    ]
    m = min(n, round(args.baseline_s * RATE_HZ))
    base = _time(
        "numpy per-sample filter (baseline)",
        m,
        lambda: run_filter_numpy(x0, P0, acc[:m], gyr[:m], dt[:m], stance[:m], ratio[:m], par),
        1,
    )
    same = _time("filter on the baseline's samples", m, lambda: filter_run(m), max(r, 5))
    ref = run_filter_numpy(x0, P0, acc[:m], gyr[:m], dt[:m], stance[:m], ratio[:m], par)
    agree = float(np.abs(filter_run(m)[0] - ref.pos_n_m).max())

    print(f"  stance (zero-velocity updates) on {stance.mean():.0%} of the samples\n")
    print(f"  {'estimator':52s} {'samples':>9s} {'samples/s':>12s} {'(CPU time)':>12s} {'x baseline':>11s}")
    for row in [*rows, same, base]:
        print(
            f"  {row.name:52s} {row.samples:9d} {row.rate:12,.0f} {row.cpu_rate:12,.0f} {row.rate / base.rate:10.1f}x"
        )
    print()
    print(f"  filter / numpy baseline on the same {m} samples: {same.rate / base.rate:.0f}x")
    print(f"  detector + filter (one batch) / numpy baseline filter: {rows[2].rate / base.rate:.0f}x")
    print(f"  compiled vs numpy filter, largest position difference: {agree:.1e} m")
    if args.gaitmap:
        g = min(n, round(args.gaitmap_s * RATE_HZ))
        gm = Timing(
            "gaitmap RtsKalman (ESKF + RTS smoother)",
            g,
            gaitmap_wall_s(args.gaitmap, acc[:g], gyr[:g], RATE_HZ, 2),
            1.0,
        )
        ours = _time(
            "detector + filter on gaitmap's samples", g, lambda: navigate(t[:g], acc[:g], gyr[:g], RATE_HZ, cfg), r
        )
        print(f"  gaitmap RtsKalman on the first {g} samples: {gm.rate:,.0f} samples/s; navigate on the same: "
              f"{ours.rate:,.0f} samples/s, {ours.rate / gm.rate:.0f}x gaitmap")  # fmt: skip
    if not args.no_compile:
        imp, cold, warm = compile_times()
        print(f"  numba compile time, first navigate() call: {cold:.1f} s with an empty cache, {warm:.2f} s cached")
        print(f"  (importing footnav.pipeline.navigation.navigator: {imp:.2f} s)")
    return 0
