"""The Python API of folders: :func:`batch` evaluates or exports many recordings, on the local cores or a Dask cluster.

The same code as ``footnav evaluate DIR`` and ``footnav export DIR -o OUTDIR`` (``footnav.app.commands.evaluate``,
``footnav.app.commands.export``, run by ``footnav.app.commands.batch``): the files found are those the commands
find, each file's result is the serial run's, and a file that fails is returned with its reason while the others
go on. On a Dask cluster (``client=``, a ``distributed.Client``; the optional extra ``footnav[dask]``) the workers
run the files: they need footnav installed and must see the files, and the output folder, at the same paths.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Literal, overload

from footnav.app.commands.batch import FileResult

if TYPE_CHECKING:
    from distributed import Client
    from footnav.app.commands.evaluate import Evaluation

PathLike = str | os.PathLike[str]


@overload
def batch(
    paths: PathLike | Sequence[PathLike], task: Literal["evaluate"] = "evaluate", *, out_dir: None = None,
    jobs: int | None = None, client: Client | None = None, smooth: bool | Literal["whole", "step"] = False,
    stance_levels: bool = True, format: str | None = None, columns: str | None = None, profile: str | None = None,
    output_format: Literal["csv", "parquet"] = "csv",
) -> list[FileResult[Evaluation]]: ...  # fmt: skip
@overload
def batch(
    paths: PathLike | Sequence[PathLike], task: Literal["export"], *, out_dir: PathLike,
    jobs: int | None = None, client: Client | None = None, smooth: bool | Literal["whole", "step"] = False,
    stance_levels: bool = True, format: str | None = None, columns: str | None = None, profile: str | None = None,
    output_format: Literal["csv", "parquet"] = "csv",
) -> list[FileResult[str]]: ...  # fmt: skip
def batch(
    paths: PathLike | Sequence[PathLike],
    task: Literal["evaluate", "export"] = "evaluate",
    *,
    out_dir: PathLike | None = None,
    jobs: int | None = None,
    client: Client | None = None,
    smooth: bool | Literal["whole", "step"] = False,
    stance_levels: bool = True,
    format: str | None = None,
    columns: str | None = None,
    profile: str | None = None,
    output_format: Literal["csv", "parquet"] = "csv",
) -> list[FileResult[Evaluation]] | list[FileResult[str]]:
    """Evaluate or export every recording in ``paths``, as ``footnav evaluate`` and ``footnav export`` do.

    Parameters
    ----------
    paths
        recordings, or folders of them (searched below; for ``export`` footnav's captures too).
    task
        ``"evaluate"``: the accuracy figures of each recording with ground truth or a closed loop;
        ``"export"``: each recording's track written to ``out_dir``.
    out_dir
        for ``export``: the folder each track goes to, as ``<name>.csv`` (or ``.parquet``) below the subfolders
        it had in a folder given.
    jobs
        local processes running files at once (None: one per core; 1: one after the other in this process).
        Not with ``client``.
    client
        a ``distributed.Client``: the files run as tasks on its cluster's workers instead.
    smooth
        False: the causal filter; True or ``"whole"``: the RTS smoother; ``"step"``: the step smoother.
    stance_levels
        hold the foot at the height of the floor it stands on (``footnav.pipeline.stance.levels``).
    format, columns, profile
        for ``export``, as the command's ``--format``, ``--columns`` and ``--profile``.
    output_format
        for ``export``: ``"csv"`` or ``"parquet"`` (the optional extra ``footnav[parquet]``).

    Returns
    -------
    list of FileResult
        one per file found, in their order (``footnav.app.commands.batch.FileResult``: ``path``, and ``value``
        or ``error``, a line saying why the file failed). ``value`` is the file's
        ``footnav.app.commands.evaluate.Evaluation`` for ``evaluate``, its summary line for ``export``.

    Raises
    ------
    FootnavError
        no recordings found, ``out_dir`` is a file, or two files would write the same track.
    TypeError
        ``export`` without ``out_dir``; options of the other task; ``jobs`` with ``client``.

    Examples
    --------
    >>> from distributed import Client  # doctest: +SKIP
    >>> from footnav.app import batch
    >>> with Client("tcp://scheduler:8786") as client:  # doctest: +SKIP
    ...     rows = [r.value for r in batch("recordings/", client=client) if r.value is not None]
    """
    if jobs is not None and client is not None:
        raise TypeError("batch() runs on local processes (jobs=) or a Dask cluster (client=), not both")
    roots = [Path(paths)] if isinstance(paths, (str, os.PathLike)) else [Path(p) for p in paths]
    how = "whole" if smooth is True else (smooth or None)
    if task == "evaluate":
        export_only = (("out_dir", out_dir), ("format", format), ("columns", columns), ("profile", profile))
        given = [name for name, value in export_only if value is not None]
        if given or output_format != "csv":
            raise TypeError(f"batch(task='evaluate') takes no {', '.join(given) or 'output_format'}: export's")
        from footnav.app.commands.evaluate import evaluate_files

        return evaluate_files(roots, how, stance_levels, jobs, client)
    if task != "export":
        raise ValueError(f"task must be 'evaluate' or 'export', got {task!r}")
    if out_dir is None:
        raise TypeError("batch(task='export') needs out_dir, the folder to write the tracks in")
    from footnav.app.commands.export import export_files

    options = {"fmt": format, "columns": columns, "profile": profile, "smooth": how, "stance_levels": stance_levels}
    return export_files(roots, Path(out_dir), jobs, client, out_format=output_format, **options)
