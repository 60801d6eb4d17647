"""``python -m benchmarks.csv_writer``: the track CSV writer, before and after (issue 27), in the same run.

A synthetic ten-minute track at 200 Hz (120 000 rows of ``footnav.app.commands.export.EXPORT_COLUMNS``: a random
walk, unit quaternions, stance flags, growing variances) is written by the writer ``footnav export`` had
(``csv.writer`` over ``f"{v:.9g}"`` of each value) and by today's (``footnav.device.files.table_csv``); the
best of ``--repeats`` wall-clock times of each, their ratio, and whether the two files are the same bytes; and the
same table written as Parquet (``footnav.device.files.table_parquet``, as ``footnav export -o TRACK.parquet``
writes it), its time as a ratio to today's CSV writer's, and its size.

Then ``footnav export DIR -o OUTDIR`` of a folder of real recordings (``--folder``, default the PyShoe VICON trials
of ``shared/data`` beside the checkout; skipped when absent) serially (``--jobs 1``) and with one process per core,
``--copies`` times over, in files per second by the wall clock (the pool's start-up included: its spawned workers
import footnav and load the compiled kernels), and whether both runs wrote the same bytes.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from footnav.app.commands.export import COLUMN_UNITS, EXPORT_COLUMNS, run_export_batch
from footnav.device.files.table_csv import write_table_csv
from footnav.device.files.table_parquet import write_table_parquet
from numpy.typing import NDArray

STANCE = EXPORT_COLUMNS.index("stance")
SHARED_FOLDER = Path(__file__).resolve().parents[2] / "shared" / "data" / "pyshoe-vicon"


def synthetic_track(rows: int, rate_hz: float = 200.0, seed: int = 0) -> NDArray[np.float64]:
    """A track-shaped table: ``rows`` rows of the export's 15 columns."""
    rng = np.random.default_rng(seed)
    t = np.arange(rows) / rate_hz
    vel = rng.normal(0.0, 0.5, (rows, 3))
    pos = np.cumsum(vel / rate_hz, axis=0)
    quat = rng.normal(size=(rows, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    stance = (np.sin(t * 2 * np.pi) > 0).astype(np.float64)
    var = np.outer(1e-6 + t * 1e-5, [1.0, 1.0, 0.3])
    return np.column_stack([t, pos, vel, quat, stance, var])


def old_writer(path: Path, table: NDArray[np.float64]) -> None:
    """The writer ``footnav export`` had before issue 27."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(EXPORT_COLUMNS)
        writer.writerows([int(v) if i == STANCE else f"{v:.9g}" for i, v in enumerate(row)] for row in table)


def new_writer(path: Path, table: NDArray[np.float64]) -> None:
    """Today's (``footnav.app.commands.export.write_track_csv``'s)."""
    write_table_csv(path, EXPORT_COLUMNS, table, frozenset({STANCE}))


def parquet_writer(path: Path, table: NDArray[np.float64]) -> None:
    """``footnav.app.commands.export.write_track_parquet``'s writing."""
    write_table_parquet(path, EXPORT_COLUMNS, table, flag_columns=frozenset({STANCE}), units=COLUMN_UNITS)


def best_of(repeats: int, run: object, *args: object) -> float:
    """The shortest wall-clock time of ``repeats`` calls of ``run(*args)``, s."""
    assert callable(run)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run(*args)
        times.append(time.perf_counter() - t0)
    return min(times)


def writer_rows(rows: int, repeats: int) -> list[str]:
    """The writer's table lines."""
    table = synthetic_track(rows)
    with tempfile.TemporaryDirectory() as tmp:
        old_path, new_path = Path(tmp) / "old.csv", Path(tmp) / "new.csv"
        new_writer(new_path, table[:10])  # compile (or load the cached machine code) outside the timing
        old_s = best_of(repeats, old_writer, old_path, table)
        new_s = best_of(repeats, new_writer, new_path, table)
        same = old_path.read_bytes() == new_path.read_bytes()
        size_mb = new_path.stat().st_size / 1e6
        parquet_path = Path(tmp) / "track.parquet"
        parquet_writer(parquet_path, table[:10])  # import pyarrow outside the timing
        parquet_s = best_of(repeats, parquet_writer, parquet_path, table)
        parquet_mb = parquet_path.stat().st_size / 1e6
    return [
        f"track CSV, {rows} rows ({size_mb:.1f} MB), best of {repeats}",
        f"  old writer (csv.writer, f-strings)   {old_s:7.3f} s",
        f"  new writer (compiled formatting)     {new_s:7.3f} s",
        f"  ratio old/new                        {old_s / new_s:7.1f} x   (target >= 10 x)",
        f"  same bytes                           {'yes' if same else 'NO'}",
        f"  Parquet writer (pyarrow, zstd)       {parquet_s:7.3f} s   ({parquet_mb:.1f} MB)",
        f"  ratio new CSV/Parquet                {new_s / parquet_s:7.1f} x",
    ]


def folder_rows(folder: Path, copies: int) -> list[str]:
    """The folder export's table lines: files per second serially and on every core, over ``copies`` copies of
    ``folder``'s files."""
    jobs = os.cpu_count() or 1
    rates, trees = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "in"
        for c in range(copies):
            shutil.copytree(folder, source / f"copy{c}")
        singles = sorted(folder.iterdir())[:3]
        t0 = time.perf_counter()
        for f in singles:  # before: one footnav process per file, as a shell loop over the folder ran it
            command = [sys.executable, "-m", "footnav.app", "export", str(f), "-o", str(Path(tmp) / "one.csv")]
            subprocess.run(command, check=True, capture_output=True)
        per_process = len(singles) / (time.perf_counter() - t0)
        for n in (1, jobs):
            out = Path(tmp) / f"jobs{n}"
            t0 = time.perf_counter()
            lines, failures = run_export_batch([source], out, n)
            rates[n] = (len(lines) + len(failures)) / (time.perf_counter() - t0)
            trees[n] = {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*.csv"))}
    files = len(trees[1])
    return [
        f"footnav export of a folder ({copies} copies of {folder}: {files} files; in-process, kernels compiled)",
        f"  one footnav process per file (before) {per_process:6.2f} files/s   (first {len(singles)} files)",
        f"  serial (--jobs 1)                    {rates[1]:7.2f} files/s",
        f"  --jobs {jobs} (one per core)             {rates[jobs]:7.2f} files/s   ({rates[jobs] / rates[1]:.2f} x)",
        f"  same bytes                           {'yes' if trees[1] == trees[jobs] else 'NO'}",
    ]


def main(argv: list[str] | None = None) -> int:
    """Print the tables; returns 1 when the two writers' files differ."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.csv_writer", description=__doc__)
    parser.add_argument("--rows", type=int, default=120_000, help="track rows (default: 10 min at 200 Hz)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each writer; the best is shown")
    parser.add_argument("--folder", type=Path, default=SHARED_FOLDER, help="recordings to export")
    parser.add_argument("--copies", type=int, default=6, help="copies of the folder's files exported (default 6)")
    args = parser.parse_args(argv)
    lines = writer_rows(args.rows, args.repeats)
    print("\n".join(lines), flush=True)
    if args.folder.is_dir():
        folder = folder_rows(args.folder, args.copies)
        print("\n".join(folder))
        lines += folder
    else:
        print(f"no folder at {args.folder}: the folder export is not measured")
    return 0 if all(line.endswith("yes") for line in lines if "same bytes" in line) else 1


if __name__ == "__main__":
    raise SystemExit(main())
