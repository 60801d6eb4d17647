"""``python -m benchmarks.dask_batch``: ``footnav evaluate DIR`` in files per second, serially, on a process pool and
on a local Dask cluster, as ratios to the serial run of the same invocation (issue 27).

The folder (``--folder``, default every recording of ``shared/data`` beside the checkout) is copied ``--copies``
times into a temporary folder and evaluated (``footnav.app.commands.evaluate.evaluate_files``, the command's own
code, in this process) four ways, each timed by the wall clock from the call to the last result:

- serial (``--jobs 1``), the kernels already loaded in this process (a first, untimed call loads them);
- the process pool on every core (``--jobs N``): its spawned workers' start-up (importing footnav, loading the
  compiled kernels) is inside the time, as it is in every run of the command;
- a ``distributed.LocalCluster`` of one single-threaded worker process per core, started before the clock (as a
  cluster a user started once), its workers not yet having run footnav: their imports are inside the time;
- the same cluster again, its workers warm, as every later run against a running cluster is.

Every run's table must equal the serial one (checked: ``repr`` of each row, every float exactly). The last lines
are the share of the machine's load other processes had during the run (``os.getloadavg``).
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from footnav.app.commands.batch import FileResult
from footnav.app.commands.evaluate import Evaluation, evaluate_files

SHARED_FOLDER = Path(__file__).resolve().parents[2] / "shared" / "data"


def timed(run: Callable[[], list[FileResult[Evaluation]]]) -> tuple[float, list[str]]:
    """(wall-clock seconds, each file's result as text) of one run."""
    t0 = time.perf_counter()
    results = run()
    seconds = time.perf_counter() - t0
    return seconds, [repr(r.value) if r.value is not None else r.error for r in results]


def evaluate_rows(folder: Path, copies: int, workers: int) -> list[str]:
    """The table's lines."""
    from distributed import Client, LocalCluster

    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "in"
        for c in range(copies):
            shutil.copytree(folder, source / f"copy{c}")
        evaluate_files([source / "copy0"], jobs=1)  # load (or compile) the kernels in this process, untimed
        load = os.getloadavg()[0]
        serial_s, serial = timed(lambda: evaluate_files([source], jobs=1))
        pool_s, pool = timed(lambda: evaluate_files([source], jobs=workers))
        t0 = time.perf_counter()
        with (
            LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
            ) as cluster,
            Client(cluster, set_as_default=False) as client,
        ):
            start_s = time.perf_counter() - t0
            cold_s, cold = timed(lambda: evaluate_files([source], client=client))
            warm_s, warm = timed(lambda: evaluate_files([source], client=client))
        load = max(load, os.getloadavg()[0])
    files = len(serial)
    failed = sum(1 for line in serial if not line.startswith("Evaluation("))
    rate = {name: files / s for name, s in (("serial", serial_s), ("pool", pool_s), ("cold", cold_s), ("warm", warm_s))}

    def row(label: str, key: str) -> str:
        return f"  {label:<44} {rate[key]:6.2f} files/s   {rate[key] / rate['serial']:5.2f} x"

    return [
        f"footnav evaluate of a folder ({copies} copies of {folder}: {files} files, {failed} failed in every run), "
        f"{workers} workers",
        row("serial (--jobs 1, kernels loaded)", "serial"),
        row(f"process pool (--jobs {workers}, start-up included)", "pool"),
        row(f"Dask LocalCluster, {workers} workers, first run", "cold"),
        row("Dask LocalCluster, the same workers again", "warm"),
        f"  (the cluster's start: {start_s:.1f} s, before the clock)",
        f"  same table                                   {'yes' if serial == pool == cold == warm else 'NO'}",
        f"  load average (1 min), highest seen           {load:.1f} on {os.cpu_count()} cores",
    ]


def main(argv: list[str] | None = None) -> int:
    """Print the table; returns 1 when a run's table differs from the serial one."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.dask_batch", description=__doc__)
    parser.add_argument("--folder", type=Path, default=SHARED_FOLDER, help="recordings to evaluate")
    parser.add_argument("--copies", type=int, default=4, help="copies of the folder's files evaluated (default 4)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="pool and cluster workers")
    args = parser.parse_args(argv)
    if not args.folder.is_dir():
        print(f"no folder at {args.folder}: nothing to measure")
        return 1
    lines = evaluate_rows(args.folder, args.copies, args.workers)
    print("\n".join(lines))
    return 0 if lines[-2].endswith("yes") else 1


if __name__ == "__main__":
    raise SystemExit(main())
