"""Folders of recordings on every core, or on a Dask cluster: ``footnav export DIR -o OUTDIR`` and ``footnav evaluate
DIR``, ``--jobs N`` or ``--scheduler tcp://HOST:PORT``.

Each file is one task of a process pool (``concurrent.futures.ProcessPoolExecutor``, spawned workers, one per core
by default); ``--jobs 1`` runs them one after the other in this process. Given a ``distributed.Client``, each file is
one task of that Dask cluster instead (``client.submit``, collected with ``distributed.as_completed``): the workers
run the same function, so they must have footnav installed and see the files (and, for ``export``, the output
folder) at the same paths, on a shared file system. Every file's result is the one the serial run gives (the same
function runs it), collected in the order of the files whatever order they finish in. A file that fails is
reported with its reason and the others go on; on a cluster, so is a file whose worker died or could not run it.
``distributed`` is the optional extra ``footnav[dask]``, imported only when a scheduler is used.
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing
import os
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Generic, TypeVar

from footnav.app.status import ProgressBar
from footnav.pipeline.errors import FootnavError

if TYPE_CHECKING:
    from distributed import Client

T = TypeVar("T")

DASK_EXTRA = "pip install 'footnav[dask]'"
SCHEDULER_TIMEOUT_S = 10.0
"""How long to wait for a ``--scheduler`` to answer, s."""


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
    task: Callable[[Path], T],
    files: list[Path],
    jobs: int | None = None,
    label: str = "files",
    client: Client | None = None,
) -> list[FileResult[T]]:
    """``task`` over ``files`` on ``jobs`` processes (default: :func:`default_jobs`; 1: in this process), or on the
    workers of ``client``'s Dask cluster when given (``jobs`` is then unused), with a progress bar on a terminal;
    the results in the order of ``files``.

    ``task`` must be picklable (a module-level function, or a ``functools.partial`` of one) for ``jobs > 1`` or a
    cluster.
    """
    bar = ProgressBar(len(files), label)
    results: list[FileResult[T] | None] = [None] * len(files)
    try:
        if client is not None:
            _run_on_cluster(client, task, files, results, bar)
        elif (jobs := min(jobs or default_jobs(), len(files))) <= 1:
            for i, f in enumerate(files):
                results[i] = _guarded(task, f)
                bar.step(f.name)
        else:
            _run_on_pool(jobs, task, files, results, bar)
    finally:
        bar.close()
    return [r for r in results if r is not None]


def _run_on_pool(
    jobs: int, task: Callable[[Path], T], files: list[Path], results: list[FileResult[T] | None], bar: ProgressBar
) -> None:
    """Fill ``results`` from a pool of ``jobs`` spawned processes, stepping ``bar`` as each file ends."""
    # spawned, not forked: no copy of this process's threads and locks (numba, the progress bar)
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(jobs, mp_context=spawn, initializer=_end_without_teardown) as pool:
        pending: dict[Future[FileResult[T]], int] = {pool.submit(_guarded, task, f): i for i, f in enumerate(files)}
        try:
            for done in as_completed(pending):
                results[pending[done]] = done.result()
                bar.step(files[pending[done]].name)
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def _end_without_teardown() -> None:
    """In each worker of the pool: end without the interpreter's teardown of numba's and LLVM's objects (0.3 s that
    the pool's shutdown waited for). Exit handlers run after the worker's process has done multiprocessing's own
    exit work (``BaseProcess._bootstrap``: finalizers, threads joined, streams flushed), and its results went out
    through a pipe as each file ended; nothing is left to the teardown. Exit code 0, as a worker's is."""
    atexit.register(os._exit, 0)


def _run_on_cluster(
    client: Client, task: Callable[[Path], T], files: list[Path], results: list[FileResult[T] | None], bar: ProgressBar
) -> None:
    """Fill ``results`` from one Dask task per file on ``client``'s cluster, stepping ``bar`` as each file ends; a
    task that errs on the worker's side (a worker that died, a task it could not unpickle) is that file's error."""
    from distributed import as_completed as completed_on_cluster

    # pure=False: each call is a task of its own, even for a file given twice or submitted again
    futures = [client.submit(_guarded, task, f, pure=False) for f in files]
    index = {future.key: i for i, future in enumerate(futures)}
    try:
        for future in completed_on_cluster(futures, loop=client.loop):
            i = index[future.key]
            if future.status == "finished":
                results[i] = future.result()
            else:
                why = future.exception() if future.status == "error" else f"task {future.status}"
                results[i] = FileResult(files[i], error=f"{files[i]}: on the Dask cluster: {type(why).__name__}: {why}")
            bar.step(files[i].name)
    except BaseException:
        client.cancel(futures)
        raise


def connect(address: str) -> Client:
    """A ``distributed.Client`` of the Dask scheduler at ``address`` (``tcp://HOST:PORT``).

    Raises
    ------
    FootnavError
        ``distributed`` is not installed (the extra ``footnav[dask]``), or no scheduler answers at ``address``
        within ``SCHEDULER_TIMEOUT_S``.
    """
    try:
        from distributed import Client
    except ImportError:
        raise FootnavError(f"--scheduler runs the files on a Dask cluster, which needs: {DASK_EXTRA}") from None
    try:
        return Client(address, timeout=SCHEDULER_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise FootnavError(f"cannot reach the Dask scheduler at {address}: {exc}") from None


@contextlib.contextmanager
def scheduler_client(address: str | None) -> Iterator[Client | None]:
    """:func:`connect` to ``address`` for the ``with`` block and close the client after it; None: no cluster."""
    if address is None:
        yield None
        return
    client = connect(address)
    try:
        yield client
    finally:
        client.close()


def export_destinations(paths: Iterable[Path], files: list[Path], out_dir: Path, suffix: str = ".csv") -> list[Path]:
    """Where each file's track goes in ``out_dir``: ``<stem><suffix>``, below the subfolders it had in a folder given.

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
        dests.append(out_dir / rel.with_suffix(suffix))
    seen: dict[Path, Path] = {}
    for f, d in zip(files, dests, strict=True):
        if d in seen:
            raise FootnavError(f"{seen[d]} and {f} would both be exported to {d}; export them apart")
        seen[d] = f
    return dests


def find_export_inputs(paths: Iterable[Path]) -> list[Path]:
    """As ``footnav.app.commands.evaluate.find_recordings``, with footnav's captures (``.mcap``) in folders too."""
    from footnav.app.commands.evaluate import find_recordings
    from footnav.device.files.capture_schema import starts_like_capture

    found: list[Path] = []
    for p in paths:
        if p.is_dir():
            captures = {q for q in p.rglob("*") if q.is_file() and starts_like_capture(q)}
            found.extend(sorted(set(find_recordings([p])) | captures))
        else:
            found.extend(find_recordings([p]))
    return found
