"""Start-up of the command line: ``footnav --help`` and every ``footnav <command> --help``, against
``python -c pass`` in the same run.

    .venv/bin/python -m benchmarks.startup [--repeats N]

Each figure is the median wall time of N fresh interpreters (``sys.executable -m footnav.app``, the
console script's entry point); the ratio to ``python -c pass`` is the figure to compare across
machines (target: at most 5x).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

COMMANDS = ("demo", "live", "calibrate", "scan", "replay", "export", "evaluate", "config", "experiment")


def median_wall_s(argv: list[str], repeats: int) -> float:
    """Median wall time of ``repeats`` runs of ``argv`` (output discarded), s."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.startup", description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=9, help="fresh interpreters per row (default 9)")
    args = ap.parse_args(argv)
    base_s = median_wall_s([sys.executable, "-c", "pass"], args.repeats)
    rows = [("python -c pass (baseline)", base_s)]
    footnav = [sys.executable, "-m", "footnav.app"]
    rows.append(("footnav --help", median_wall_s([*footnav, "--help"], args.repeats)))
    for command in COMMANDS:
        rows.append((f"footnav {command} --help", median_wall_s([*footnav, command, "--help"], args.repeats)))
    print(f"  {'command':32} {'median s':>9} {'x baseline':>11}")
    for name, wall_s in rows:
        print(f"  {name:32} {wall_s:9.3f} {wall_s / base_s:10.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
