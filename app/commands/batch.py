"""Folders of recordings on every core: ``footnav export DIR -o OUTDIR`` and ``footnav evaluate DIR``, ``--jobs N``.

Each file is one task of a process pool (``concurrent.futures.ProcessPoolExecutor``, spawned workers, one per core
by default); ``--jobs 1`` runs them one after the other in this process. Every file's result is the one the serial
run gives (the same function runs it), collected in the order of the files whatever order they finish in. A file
that fails is reported with its reason and the others go on.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterable
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Generic, TypeVar

from footnav.app.status import ProgressBar
from footnav.pipeline.errors import FootnavError

T = TypeVar("T")


@dataclass(frozen=True)
class FileResult(Generic[T]):
    """One file's outcome: ``value`` when it went through, else ``error`` (one line)."""

    path: Path
    value: T | None = None
    error: str = ""


def default_jobs() -> int:
    """One worker per core."""
    return os.cpu_count() or 1


def _guarded(task: Callable[[Path], T], path: Path) -> FileResult[T]:
    """``task(path)`` with any error (but an interrupt) turned into the file's ``error``."""
    try:
        return FileResult(path, value=task(path))
    except FootnavError as exc:
        return FileResult(path, error=str(exc))
    except Exception as exc:  # one broken file must not stop the others: reported per file
        return FileResult(path, error=f"{path}: {type(exc).__name__}: {exc}")


def run_files(
    task: Callable[[Path], T], files: list[Path], jobs: int | None = None, label: str = "files"
) -> list[FileResult[T]]:
    """``task`` over ``files`` on ``jobs`` processes (default: :func:`default_jobs`; 1: in this process), with a
    progress bar on a terminal; the results in the order of ``files``.

    ``task`` must be picklable (a module-level function, or a ``functools.partial`` of one) for ``jobs > 1``.
    """
    jobs = min(jobs or default_jobs(), len(files))
    bar = ProgressBar(len(files), label)
    results: list[FileResult[T] | None] = [None] * len(files)
    try:
        if jobs <= 1:
            for i, f in enumerate(files):
                results[i] = _guarded(task, f)
                bar.step(f.name)
        else:
            # spawned, not forked: no copy of this process's threads and locks (numba, the progress bar)
            with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
                pending: dict[Future[FileResult[T]], int] = {
                    pool.submit(_guarded, task, f): i for i, f in enumerate(files)
                }
                try:
                    for done in as_completed(pending):
                        results[pending[done]] = done.result()
                        bar.step(files[pending[done]].name)
                except BaseException:
                    pool.shutdown(wait=False, cancel_futures=True)
                    raise
    finally:
        bar.close()
    return [r for r in results if r is not None]


def export_destinations(paths: Iterable[Path], files: list[Path], out_dir: Path) -> list[Path]:
    """Where each file's track goes in ``out_dir``: ``<stem>.csv``, below the subfolders it had in a folder given.

    Raises
    ------
    FootnavError
        two files would write the same track.
    """
    roots = [p for p in paths if p.is_dir()]
    dests: list[Path] = []
    for f in files:
        root = next((r for r in roots if f.is_relative_to(r)), None)
        rel = f.relative_to(root) if root is not None else Path(f.name)
        dests.append(out_dir / rel.with_suffix(".csv"))
    seen: dict[Path, Path] = {}
    for f, d in zip(files, dests, strict=True):
        if d in seen:
            raise FootnavError(f"{seen[d]} and {f} would both be exported to {d}; export them apart")
        seen[d] = f
    return dests


def find_export_inputs(paths: Iterable[Path]) -> list[Path]:
    """As ``footnav.app.commands.evaluate.find_recordings``, with footnav's captures (``.mcap``) in folders too."""
    from footnav.app.commands.evaluate import find_recordings
    from footnav.app.commands.export import _is_capture

    found: list[Path] = []
    for p in paths:
        if p.is_dir():
            captures = {q for q in p.rglob("*") if q.is_file() and _is_capture(q)}
            found.extend(sorted(set(find_recordings([p])) | captures))
        else:
            found.extend(find_recordings([p]))
    return found
