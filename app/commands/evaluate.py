"""``footnav evaluate``: accuracy over recordings with ground truth or a known closed loop.

For each recording: ATE in 2D and 3D after a 4-DoF (yaw + translation) alignment with the mirror
test, the PyShoe paper's ARMSE-2D, the end-point error, and for closed walks the loop-closure error;
errors also as a percentage of the distance walked. One default configuration for every file.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from footnav.app.commands.export import lead_in_note, navigate_recording
from footnav.app.status import input_handling
from footnav.device.files.capture_schema import starts_like_capture
from footnav.device.files.recordings import CsvMapping, Recording, detect_format, load_recording
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.metrics import armse_2d_pyshoe, ate, loop_closure_error, path_length_m
from numpy.typing import NDArray

if TYPE_CHECKING:
    from distributed import Client
    from footnav.app.commands.batch import FileResult

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Evaluation:
    """Figures for one recording (NaN where they do not apply)."""

    name: str
    format: str
    samples: int
    distance_m: float
    armse_2d_m: float = math.nan
    ate_2d_m: float = math.nan
    ate_3d_m: float = math.nan
    mirrored: bool = False
    end_point_m: float = math.nan
    loop_3d_m: float = math.nan
    loop_2d_m: float = math.nan
    handling: str = ""
    """What was done with doubtful input (``footnav.app.status.input_handling``; empty: nothing)."""
    feet: str = ""
    """Of a pair of feet (:func:`evaluate_pair`): ``"coupled"`` or ``"independent"``; empty for one foot."""
    coupling: str = ""
    """Of a coupled pair: what the coupling did (``footnav.app.api.feet.coupling_counts``)."""

    @property
    def end_point_pct(self) -> float:
        return 100.0 * self.end_point_m / self.distance_m

    @property
    def loop_pct(self) -> float:
        return 100.0 * self.loop_3d_m / self.distance_m


@dataclass(frozen=True)
class Reading:
    """How to read the recordings: ``--format``, ``--columns`` and ``--profile`` as ``export`` takes them (None:
    detected from the file, the default columns, the format's unit profile)."""

    format: str | None = None
    columns: str | None = None
    profile: str | None = None


def evaluate_file(
    path: Path, smooth: str | None = None, stance_levels: bool = True, reading: Reading = Reading()
) -> Evaluation:
    """Navigate one recording (smoothed when ``smooth`` is one of ``footnav.app.commands.export.SMOOTHING``) and measure
    it (with the stance height levels unless told not to).

    Raises
    ------
    FootnavError
        the file is not a recording footnav reads, has no ground truth and is not a known closed loop
        (a footnav capture among them), or never stands still.
    """
    rec = _measurable(path, reading)
    nav, stats = navigate_recording(rec, reading.profile, smooth, stance_levels)
    # scored from the first still period, where the track's frame is defined, as before the samples before it were
    # navigated (backwards from it, ``footnav.pipeline.navigation.lead_in``): the figures stay comparable
    lead_in = f"{note} (not scored)" if (note := lead_in_note(stats).removeprefix(", ")) else ""
    handling = ", ".join(h for h in (input_handling(stats), lead_in) if h)
    est = nav.pos_n_m[stats.samples_navigated_backwards :]
    return score(rec, est, stats.samples_before_alignment, name=rec.name, samples=len(nav), handling=handling)


def score(
    rec: Recording,
    est_n_m: F64,
    skipped: int,
    *,
    name: str,
    samples: int,
    handling: str = "",
    feet: str = "",
    coupling: str = "",
) -> Evaluation:
    """The figures of one foot's track ``est_n_m`` (m, samples ``skipped`` on of ``rec``) against the recording's
    ground truth, or its loop closure when it has none."""
    if rec.gt_pos_m is not None:
        gt = rec.gt_pos_m[skipped:] - rec.gt_pos_m[skipped]
        fit = ate(est_n_m, gt, mirror_test=True)
        est_for_end = est_n_m * np.array([1.0, -1.0, 1.0]) if fit.mirrored else est_n_m
        c, s = math.cos(fit.yaw_rad), math.sin(fit.yaw_rad)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        aligned = (est_for_end - est_for_end.mean(axis=0)) @ rot.T + gt.mean(axis=0)
        return Evaluation(
            name=name,
            format=rec.format,
            samples=samples,
            distance_m=path_length_m(gt[:: max(1, round(rec.rate_hz / 20))]),
            armse_2d_m=armse_2d_pyshoe(est_for_end, gt),
            ate_2d_m=fit.rmse_2d_m,
            ate_3d_m=fit.rmse_3d_m,
            mirrored=fit.mirrored,
            end_point_m=float(np.linalg.norm(aligned[-1] - gt[-1])),
            handling=handling,
            feet=feet,
            coupling=coupling,
        )
    loop_3d, loop_2d = loop_closure_error(est_n_m)
    return Evaluation(
        name=name,
        format=rec.format,
        samples=samples,
        distance_m=path_length_m(est_n_m[:: max(1, round(rec.rate_hz / 20))]),
        loop_3d_m=loop_3d,
        loop_2d_m=loop_2d,
        end_point_m=loop_3d,
        handling=handling,
        feet=feet,
        coupling=coupling,
    )


def evaluate_pair(
    left: Path,
    right: Path,
    *,
    independent_only: bool = False,
    heading: bool = True,
    stance_levels: bool = True,
    reading: Reading = Reading(),
) -> list[Evaluation]:
    """A left and a right recording navigated together (``footnav.app.api.feet.navigate_pair``), each foot
    measured as :func:`evaluate_file` measures one: coupled by the inter-foot distance bound (and, when
    ``heading``, the default, their relative heading in stance: ``footnav.pipeline.two_feet.heading``), then independent
    (only independent when ``independent_only``).

    Raises
    ------
    FootnavError
        a file cannot be read or measured, or the two do not overlap in time.
    """
    from footnav.app.api.feet import coupling_counts, navigate_pair
    from footnav.pipeline.two_feet.live import coupling_bound

    recs = [_measurable(p, reading) for p in (left, right)]
    rows: list[Evaluation] = []
    bound = coupling_bound("distance+heading" if heading else "distance")
    for coupled in (False,) if independent_only else (True, False):
        result = navigate_pair(
            recs[0], recs[1], coupled=coupled, bound=bound, stance_levels=stance_levels, profile=reading.profile
        )
        how = "coupled" if coupled else "independent"
        counts = coupling_counts(result, bound) if coupled and bound is not None else ""
        feet = ((result.left, result.left_stats), (result.right, result.right_stats))
        for side, rec, (nav, stats) in zip(("L", "R"), recs, feet, strict=True):
            assert nav is not None  # navigate_pair raises otherwise
            name = f"{side} {how} {rec.name}"
            skipped, handling = stats.samples_before_alignment, input_handling(stats)
            rows.append(
                score(
                    rec, nav.pos_n_m, skipped, name=name, samples=len(nav), handling=handling, feet=how, coupling=counts
                )
            )
    return rows


def pair_summary(rows: list[Evaluation]) -> str:
    """One line per way of navigating the feet: the two feet's mean ATE-2D (or 2D loop closure) and end-point
    error, and the coupled solution's change against the independent one, %."""
    lines = []
    means: dict[str, float] = {}
    for how in ("coupled", "independent"):
        feet = [r for r in rows if r.feet == how]
        if not feet:
            continue
        err = [r.ate_2d_m if not math.isnan(r.ate_2d_m) else r.loop_2d_m for r in feet]
        means[how] = float(np.mean(err))
        end = float(np.mean([r.end_point_m for r in feet]))
        what = "ATE-2D" if not math.isnan(feet[0].ate_2d_m) else "loop closure 2D"
        counts = f" ({feet[0].coupling})" if feet[0].coupling else ""
        lines.append(f"two feet {how + ':':<13} mean {what} {means[how]:.3f} m, end point {end:.3f} m{counts}")
    if len(means) == 2:
        change = 100.0 * (means["coupled"] / means["independent"] - 1.0)
        lines.append(f"coupled against independent: {change:+.1f} % mean {what}")
    return "\n".join(lines)


def _measurable(path: Path, reading: Reading) -> Recording:
    """The recording at ``path``, read as ``reading`` says, refused when there is nothing to measure it against."""
    if starts_like_capture(path):
        raise FootnavError(
            f"{path} is a footnav capture: it records no ground truth and no known closed loop, so there is "
            "nothing to measure it against (`footnav export` writes its track, `footnav replay` shows it)"
        )
    rec = load_recording(path, reading.format, CsvMapping.parse(reading.columns) if reading.columns else None)
    if rec.gt_pos_m is None and not rec.closed_loop:
        raise FootnavError(f"{path}: no ground truth and not a known closed loop; nothing to measure against")
    return rec


def find_recordings(paths: Iterable[Path]) -> list[Path]:
    """Files given, and recordings of a known format inside folders given (sorted)."""
    found: list[Path] = []
    for p in paths:
        if p.is_dir():
            for f in sorted(q for q in p.rglob("*") if q.is_file()):
                try:
                    if detect_format(f) != "csv" or f.suffix.lower() == ".csv":
                        found.append(f)
                except FootnavError:
                    continue
        elif p.exists():
            found.append(p)
        else:
            raise FootnavError(f"{p}: no such file or folder")
    return found


def _fmt(v: float, width: int = 8, digits: int = 3) -> str:
    return f"{'-':>{width}}" if math.isnan(v) else f"{v:>{width}.{digits}f}"


def format_table(rows: list[Evaluation]) -> str:
    """The per-file table and a summary, as text."""
    head = (
        f"{'recording':<24} {'format':<8} {'dist m':>7} {'ARMSE2D':>8} {'ATE2D':>8} {'ATE3D':>8} {'mirror':>6} "
        f"{'end m':>8} {'end %':>6} {'loop3D':>8} {'loop2D':>8} {'loop %':>6}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r.name[:24]:<24} {r.format:<8} {r.distance_m:>7.1f} {_fmt(r.armse_2d_m)} {_fmt(r.ate_2d_m)} "
            f"{_fmt(r.ate_3d_m)} {'yes' if r.mirrored else 'no':>6} {_fmt(r.end_point_m)} "
            f"{_fmt(r.end_point_pct, 6, 2)} {_fmt(r.loop_3d_m)} {_fmt(r.loop_2d_m)} {_fmt(r.loop_pct, 6, 2)}"
        )
    # per file; two feet's rows are summed up by ``pair_summary``
    armse = np.array([r.armse_2d_m for r in rows if not (math.isnan(r.armse_2d_m) or r.feet)])
    loops = [r for r in rows if not (math.isnan(r.loop_3d_m) or r.feet)]
    lines.append("")
    if armse.size:
        lines.append(
            f"ground truth ({armse.size} files): ARMSE-2D mean {armse.mean():.3f} m, median {np.median(armse):.3f} m, "
            f"max {armse.max():.3f} m"
        )
    if loops:
        lines.append(
            f"closed loops ({len(loops)} files): loop closure 3D mean {np.mean([r.loop_3d_m for r in loops]):.3f} m, "
            f"2D mean {np.mean([r.loop_2d_m for r in loops]):.3f} m"
        )
    handled = [r for r in rows if r.handling]
    if handled:
        lines.append("input handling:")
        lines.extend(f"  {r.name}: {r.handling}" for r in handled)
    return "\n".join(lines)


def evaluate_files(
    paths: list[Path],
    smooth: str | None = None,
    stance_levels: bool = True,
    jobs: int | None = 1,
    client: Client | None = None,
    reading: Reading = Reading(),
) -> list[FileResult[Evaluation]]:
    """Evaluate every recording found, on ``jobs`` processes (None: one per core) or on ``client``'s Dask cluster
    (``footnav.app.commands.batch.run_files``); each file's :class:`Evaluation` or failure, in the order of the files.

    Raises
    ------
    FootnavError
        no recordings found in ``paths``.
    """
    from footnav.app.commands.batch import run_files

    files = find_recordings(paths)
    if not files:
        raise FootnavError("no recordings found in " + ", ".join(str(p) for p in paths))
    task = partial(evaluate_file, smooth=smooth, stance_levels=stance_levels, reading=reading)
    return run_files(task, files, jobs, "evaluate", client=client)


def run_evaluate(
    paths: list[Path],
    smooth: str | None = None,
    stance_levels: bool = True,
    jobs: int | None = 1,
    client: Client | None = None,
    reading: Reading = Reading(),
) -> tuple[list[Evaluation], list[str]]:
    """:func:`evaluate_files`, as the rows and one-line problems (files that failed), in the order of the files."""
    results = evaluate_files(paths, smooth, stance_levels, jobs, client, reading)
    return [r.value for r in results if r.value is not None], [r.error for r in results if r.error]
