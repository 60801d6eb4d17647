"""Start-up of the command line: ``footnav --help`` and every ``footnav <command> --help``, against
``python -c pass`` in the same run.

    .venv/bin/python -m benchmarks.startup [--repeats N] [--export-minutes M]

Each figure is the median wall time of N fresh interpreters (``sys.executable -m footnav.app``, the
console script's entry point), with their median CPU time (user + system) beside it, which the shared
machine's other load disturbs less; the ratio to ``python -c pass`` is the figure to compare across
machines (target: at most 5x). Then ``footnav export`` of an emulated walk of M minutes at 200 Hz
written as a generic CSV (120 000 samples by default): with the numba cache warm (target: at most 1 s
beyond ``python -c pass``), and once in a fresh interpreter with an empty cache (the first run after
installing: compiling its kernels, target: at most 10 s of compiling). Every interpreter caches
bytecode as Python does by default, in a folder of its own (``PYTHONPYCACHEPREFIX``; a machine that sets
``PYTHONDONTWRITEBYTECODE`` would otherwise compile footnav's sources in every run, which no installed
copy does), and each command runs once unmeasured first.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

COMMANDS = ("demo", "live", "calibrate", "scan", "replay", "export", "evaluate", "config", "experiment")


def user_env(pycache: Path) -> dict[str, str]:
    """This process's environment with Python's default bytecode caching, into ``pycache``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return env | {"PYTHONPYCACHEPREFIX": str(pycache)}


def median_times_s(argv: list[str], repeats: int, env: dict[str, str], warm_up: bool = True) -> tuple[float, float]:
    """Median wall time and median CPU time (user + system, the process and its children) of ``repeats`` runs of
    ``argv`` (output discarded), after one unmeasured run if ``warm_up``, s."""
    if warm_up:
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, env=env)
    walls, cpus = [], []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True, env=env)
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return statistics.median(walls), statistics.median(cpus)


def write_walk_csv(path: Path, minutes: float, rate_hz: float = 200.0) -> int:
    """An emulated rectangle walk (MPU-6500-class errors) as a generic CSV (``t,ax..az,gx..gz``, SI);
    returns its number of samples."""
    from footnav.device.emulator.motion.gait import simulate_walk
    from footnav.device.emulator.sensors.imu_errors import corrupt

    truth = simulate_walk("rectangle", minutes * 60.0, rate_hz, seed=1)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, rate_hz, "mpu6500x4", seed=2)
    table = np.column_stack([truth.t_s, acc, gyr])
    np.savetxt(path, table, delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.9g")
    return len(truth)


def export_rows(minutes: float, repeats: int, env: dict[str, str]) -> list[tuple[str, float, float]]:
    """``footnav export`` of a ``minutes``-long walk: warm cache (median of ``repeats``), then one run
    with an empty numba cache."""
    with tempfile.TemporaryDirectory() as work:
        csv = Path(work) / "walk.csv"
        n = write_walk_csv(csv, minutes)
        argv = [sys.executable, "-m", "footnav.app", "export", str(csv), "-o", str(Path(work) / "track.csv")]
        warm = median_times_s(argv, repeats, env)
        empty_cache = str(Path(work) / "empty-cache")
        cold = median_times_s(argv, 1, env | {"NUMBA_CACHE_DIR": empty_cache}, warm_up=False)
    name = f"footnav export, {minutes:g} min at 200 Hz ({n} samples)"
    return [(f"{name}, cache warm", *warm), ("the same, first run (empty cache)", *cold)]


def _rows(repeats: int, export_minutes: float, env: dict[str, str]) -> list[tuple[str, float, float]]:
    """(name, median wall s, median CPU s) of the baseline, the help of every command and the exports."""
    rows = [("python -c pass (baseline)", *median_times_s([sys.executable, "-c", "pass"], repeats, env))]
    footnav = [sys.executable, "-m", "footnav.app"]
    rows.append(("footnav --help", *median_times_s([*footnav, "--help"], repeats, env)))
    for command in COMMANDS:
        rows.append((f"footnav {command} --help", *median_times_s([*footnav, command, "--help"], repeats, env)))
    if export_minutes > 0:
        rows += export_rows(export_minutes, max(3, repeats // 3), env)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.startup", description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=9, help="fresh interpreters per row (default 9)")
    ap.add_argument(
        "--export-minutes", type=float, default=10.0, help="minutes of 200 Hz walk footnav export runs on (10; 0: skip)"
    )
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as pycache:
        rows = _rows(args.repeats, args.export_minutes, user_env(Path(pycache)))
    base_s, base_cpu_s = rows[0][1:]
    print(f"  {'command':60} {'median s':>9} {'x baseline':>11} {'CPU s':>7}")
    for name, wall_s, cpu_s in rows:
        print(f"  {name:60} {wall_s:9.3f} {wall_s / base_s:10.1f}x {cpu_s:7.3f}")
    if args.export_minutes > 0:
        (_, warm, warm_cpu), (_, cold, _) = rows[-2:]
        print(
            f"\n  footnav export: {warm - base_s:.2f} s beyond python -c pass with the cache warm (target 1 s; "
            f"CPU time {warm_cpu - base_cpu_s:.2f} s beyond);"
        )
        print(f"  a first run {cold - warm:.1f} s more (empty numba cache: compiling its kernels; target 10 s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
