"""``footnav export``: a recording -> one CSV (or Parquet) row per sample of the navigation solution.

A recording from another tool is loaded (``footnav.device.files.recordings``) and navigated here; a footnav capture
(``.mcap``) is replayed headless through the same device decoding and pipeline as ``footnav replay``
(so its rows are the live estimates, bit for bit), one file per foot, and a ToF unit's rows carry its
clearance too (:data:`CLEARANCE_COLUMNS`). The track is CSV, or Parquet (``footnav.device.files.table_parquet``)
for an output named ``.parquet`` or ``--output-format parquet``: the same columns and values, every bit kept.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from footnav.app.status import input_handling, lead_in_note
from footnav.device.files.capture_schema import starts_like_capture
from footnav.device.files.numeric_csv import build_kernel as build_reader_kernel
from footnav.device.files.recordings import CsvMapping, Recording, load_recording
from footnav.device.files.table_csv import build_kernel as build_csv_kernel
from footnav.device.files.table_csv import write_table_csv
from footnav.device.files.table_parquet import require_pyarrow, write_table_parquet
from footnav.pipeline.aiding.tof_types import TofConfig
from footnav.pipeline.errors import FootnavError, InputFormatError
from footnav.pipeline.gait.steps import segment_steps
from footnav.pipeline.gait.tof_clearance import swing_clearance
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.lead_in import RecordingRun, navigate_every_sample
from footnav.pipeline.navigation.navigator import NavConfig, NavStats, navigate
from footnav.pipeline.navigation.profiles import get_profile
from footnav.pipeline.navigation.saturation import SaturatedRates, reconstruct_saturated_rates
from footnav.pipeline.navigation.warm import build_kernels
from numpy.typing import NDArray

if TYPE_CHECKING:
    from distributed import Client
    from footnav.app.commands.batch import FileResult

EXPORT_COLUMNS = (
    "t",
    "x",
    "y",
    "z",
    "vx",
    "vy",
    "vz",
    "qw",
    "qx",
    "qy",
    "qz",
    "stance",
    "var_x",
    "var_y",
    "var_z",
)


SMOOTHING = ("whole", "step")
"""``smooth`` choices: the RTS smoother of the whole recording (``footnav.pipeline.smoothing.rts``), or step by step
as a live session shows the track once each step has ended (``footnav.pipeline.smoothing.stepwise``)."""


def recording_config(rec: Recording, profile: str | None = None, stance_levels: bool = True) -> NavConfig:
    """The navigator's configuration for ``rec``: its unit profile (or ``profile``), with or without the stance
    height levels.

    Raises
    ------
    FootnavError
        the profile is not a built-in one.
    """
    try:
        unit = get_profile(profile or rec.profile)
    except KeyError as exc:  # a recording is navigated with a built-in profile
        raise FootnavError(f"{rec.name}: {exc.args[0]}") from None
    return NavConfig(profile=unit, stance_levels=stance_levels)


def navigate_recording(
    rec: Recording, profile: str | None = None, smooth: str | None = None, stance_levels: bool = True
) -> tuple[NavBatch, NavStats]:
    """Run the navigator (and a smoother when asked: one of ``SMOOTHING``) over a whole recording,
    with the stance height levels unless ``stance_levels`` is False (``footnav.pipeline.stance.levels``).

    The gyroscope's saturated stretches are reconstructed first (``footnav.pipeline.navigation.saturation``: this needs
    the whole recording, so it happens here and not in the live navigator). Every sample is navigated: a recording
    that starts in motion has its samples before the first still period navigated backwards in time from it
    (``footnav.pipeline.navigation.lead_in``; counted in ``NavStats.samples_navigated_backwards``).

    Raises
    ------
    FootnavError
        the recording never stands still, so it cannot be aligned.
    """
    config = recording_config(rec, profile, stance_levels)
    sat = reconstruct_saturated_rates(rec.t_s, rec.gyr_b_radps)
    run: RecordingRun = navigate
    if smooth == "whole":
        from footnav.pipeline.smoothing.rts import smooth_recording

        run = smooth_recording
    elif smooth == "step":
        from footnav.pipeline.smoothing.stepwise import step_smooth_recording

        run = step_smooth_recording
    elif smooth is not None:
        raise ValueError(f"smooth must be one of {SMOOTHING} or None, got {smooth!r}")
    nav, stats = navigate_every_sample(
        rec.t_s, rec.acc_b_mps2, sat.gyr_b_radps, rec.rate_hz, config, run=run, gyr_clipped_b=sat.clipped_b
    )
    if nav is None:
        raise FootnavError(
            f"{rec.name}: the unit is never still for {config.align_s:.1f} s, so roll and pitch cannot be "
            "aligned; a recording must start (or at least include) a moment of standing still"
        )
    count_clipped_rates(stats, sat)
    return nav, stats


def count_clipped_rates(stats: NavStats, sat: SaturatedRates) -> None:
    """Put what the saturated-rate reconstruction did into a navigator's counts (``input_handling`` tells it)."""
    stats.rates_reconstructed = sat.reconstructed
    stats.rates_clipped = int(np.count_nonzero(sat.clipped_b))


CLEARANCE_COLUMNS = ("clearance", "clearance_swing", "floor_z")
"""Added for a ToF unit: the live clearance above the floor under the IMU, the one from each swing's
hits past and future (``footnav.pipeline.gait.tof_clearance``), and the height of that floor, m (NaN before the
unit's first range reading, where the clearance is the height above the start floor)."""


TRACK_FORMATS = {"csv": ".csv", "parquet": ".parquet"}
"""The track's file formats (``--output-format``) and their suffixes."""

COLUMN_UNITS = {
    "t": "s",
    **dict.fromkeys(("x", "y", "z", *CLEARANCE_COLUMNS), "m"),
    **dict.fromkeys(("vx", "vy", "vz"), "m/s"),
    **dict.fromkeys(("qw", "qx", "qy", "qz", "stance"), "1"),
    **dict.fromkeys(("var_x", "var_y", "var_z"), "m^2"),
}
"""The unit of each track column (kept in a Parquet file's schema)."""


def track_table(nav: NavBatch) -> tuple[tuple[str, ...], NDArray[np.float64]]:
    """The track's column names (``EXPORT_COLUMNS``, and for a ToF unit ``CLEARANCE_COLUMNS``) and its (n, columns)
    values: SI units, navigation frame right-handed z up, origin at the start."""
    var = np.diagonal(nav.pos_cov_n_m2, axis1=1, axis2=2)
    columns = [nav.t_s, nav.pos_n_m, nav.vel_n_mps, nav.quat_nb_wxyz, nav.stance.astype(np.float64), var]
    names: tuple[str, ...] = EXPORT_COLUMNS
    if nav.floor_z_m is not None and nav.ranges is not None:
        swing = swing_clearance(nav.t_s, nav.pos_n_m, nav.stance, nav.clearance_m, nav.ranges, TofConfig().snap_m)
        columns += [nav.clearance_m, swing, nav.floor_z_m]
        names = EXPORT_COLUMNS + CLEARANCE_COLUMNS
    return names, np.column_stack(columns)


def write_track_csv(nav: NavBatch, path: Path) -> None:
    """Write :func:`track_table` as CSV."""
    names, table = track_table(nav)
    # the bytes csv.writer wrote for f"{v:.9g}" of each value (int for the stance), formatted compiled
    write_table_csv(path, names, table, frozenset({EXPORT_COLUMNS.index("stance")}))


def write_track_parquet(nav: NavBatch, path: Path) -> None:
    """Write :func:`track_table` as Parquet: float64 columns, the stance boolean, each column's unit
    (:data:`COLUMN_UNITS`) in the schema.

    Raises
    ------
    MissingExtraError
        pyarrow is not installed (``pip install 'footnav[parquet]'``).
    """
    names, table = track_table(nav)
    frame = "navigation frame: right-handed, z up, origin at the start position; SI units"
    write_table_parquet(
        path,
        names,
        table,
        flag_columns=frozenset({EXPORT_COLUMNS.index("stance")}),
        units=COLUMN_UNITS,
        metadata={"footnav.track": frame},
    )


def track_format(path: Path, out_format: str | None = None) -> str:
    """The format a track written to ``path`` takes: ``out_format``, or else ``parquet`` for a ``.parquet`` name and
    ``csv`` for any other.

    Raises
    ------
    FootnavError
        ``path``'s suffix names the other format, or Parquet is asked for without pyarrow installed.
    """
    by_name = "parquet" if path.suffix.lower() == ".parquet" else "csv"
    if out_format is None:
        out_format = by_name
    elif out_format not in TRACK_FORMATS:
        raise ValueError(f"out_format must be one of {tuple(TRACK_FORMATS)} or None, got {out_format!r}")
    elif path.suffix.lower() in TRACK_FORMATS.values() and by_name != out_format:
        raise FootnavError(f"{path} is named {path.suffix} but --output-format is {out_format}; name it alike")
    if out_format == "parquet":
        require_pyarrow()  # before any work
    return out_format


def write_track(nav: NavBatch, path: Path, out_format: str | None = None) -> None:
    """Write the track as :func:`track_format` says: :func:`write_track_csv` or :func:`write_track_parquet`."""
    if track_format(path, out_format) == "parquet":
        write_track_parquet(nav, path)
    else:
        write_track_csv(nav, path)


def _write_csv(path: Path, header: tuple[str, ...], rows: Iterable[list[int | str]]) -> None:
    """``header`` and ``rows`` to ``path``; a file that cannot be written is a ``FootnavError``."""
    try:
        with path.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(header)
            writer.writerows(rows)
    except OSError as exc:
        raise FootnavError(f"cannot write {path}: {exc.strerror}") from None


STEP_COLUMNS = (
    "t",
    "index",
    "dx",
    "dy",
    "dz",
    "dyaw",
    "is_step",
    "length",
    "duration",
    "clearance_max",
    "x",
    "y",
    "z",
    "yaw",
    "c_xx",
    "c_xy",
    "c_xz",
    "c_xyaw",
    "c_yy",
    "c_yz",
    "c_yyaw",
    "c_zz",
    "c_zyaw",
    "c_yawyaw",
)
"""``--steps``: OpenShoe's stepwise output computed from the track (``footnav.pipeline.gait.steps``), one row per
step epoch (the end of a stance): its time and sample index in the track; the displacement since the
previous epoch in that epoch's heading frame (x forward, z up), m, and the heading change, rad;
whether it is a step (5 cm or more; else standing); its horizontal length, m, and duration, s; the
largest clearance between the two epochs, m; the position and heading at the epoch (navigation
frame); and the upper triangle of the 4×4 covariance of (dx, dy, dz, dyaw), m² and rad² (empty for
a smoothed track: the smoother gives no covariance between two epochs, which a step's needs)."""


def write_steps_csv(nav: NavBatch, path: Path, *, with_covariance: bool = True) -> str:
    """Write ``STEP_COLUMNS`` for the steps of ``nav``; returns what was written, for the summary."""
    assert nav.cov_pos_yaw is not None
    steps = segment_steps(nav.t_s, nav.pos_n_m, nav.quat_nb_wxyz, nav.stance, nav.cov_pos_yaw)
    starts = np.concatenate([[0], steps.index[:-1]]).astype(np.intp)[: len(steps.index)]
    duration = steps.t_s - nav.t_s[starts]
    clearance = np.array([float(np.max(nav.clearance_m[a : b + 1])) for a, b in zip(starts, steps.index, strict=True)])
    upper = np.triu_indices(4)
    cov = steps.cov[:, upper[0], upper[1]] if with_covariance else np.full((len(steps), 10), np.nan)
    table = np.column_stack(
        [
            steps.t_s,
            steps.index,
            steps.dpos_step_m,
            steps.dyaw_rad,
            steps.is_step,
            np.linalg.norm(steps.dpos_step_m[:, :2], axis=1),
            duration,
            clearance,
            steps.pos_n_m,
            steps.yaw_rad,
            cov,
        ]
    )
    integer = {STEP_COLUMNS.index("index"), STEP_COLUMNS.index("is_step")}
    _write_csv(
        path,
        STEP_COLUMNS,
        ([int(v) if i in integer else ("" if np.isnan(v) else f"{v:.9g}") for i, v in enumerate(row)] for row in table),
    )
    return f"{int(np.count_nonzero(steps.is_step))} steps ({len(steps)} rows) to {path}"


def run_export(
    source: Path,
    out: Path,
    *,
    fmt: str | None,
    columns: str | None,
    profile: str | None,
    smooth: str | None,
    stance_levels: bool = True,
    steps_out: Path | None = None,
    gait_out: Path | None = None,
    out_format: str | None = None,
) -> str:
    """Load, navigate and write the track (as :func:`write_track`, in ``out_format`` or as ``out``'s suffix says;
    and, with ``steps_out``, its steps; with ``gait_out``, its strides' gait parameters,
    ``footnav.app.api.gait_export``); returns a one-line summary (and the gait's summary line)."""
    written_as = track_format(out, out_format)  # a name that contradicts the format is refused before any work
    # on a first run the CSV kernels (the writer's, and the reader's for a recording) compile while a child compiles
    # the filter's
    build_writer = build_csv_kernel if written_as == "csv" else None
    if starts_like_capture(source):
        options = (("--format", fmt), ("--columns", columns), ("--profile", profile))
        given = [name for name, v in options if v] + ([] if stance_levels else ["--no-stance-levels"])
        if given:
            raise FootnavError(
                f"{source} is a footnav capture, exported with the settings it was recorded with; "
                f"drop {', '.join(given)}"
            )
        build_kernels(build_writer)
        return export_capture(source, out, steps_out, smooth=smooth, gait_out=gait_out, out_format=out_format)
    rec = load_other_recording(source, fmt, columns)
    build_kernels(lambda: _build_csv_kernels(build_writer))
    nav, stats = navigate_recording(rec, profile, smooth, stance_levels)
    write_track(nav, out, out_format)
    # a step's covariance is the growth of the causal filter's between its epochs; the lead-in's shrinks towards
    # the still period it was navigated back from, so a track with one has no step covariance, as a smoothed one
    with_covariance = smooth is None and not stats.samples_navigated_backwards
    steps = "" if steps_out is None else f", {write_steps_csv(nav, steps_out, with_covariance=with_covariance)}"
    skipped = lead_in_note(stats)
    handled = f"; {h}" if (h := input_handling(stats)) else ""
    gait = ""
    if gait_out is not None:
        from footnav.app.api.gait_export import export_gait

        gait = "\n" + export_gait(nav, gait_out, causal_from=None if smooth else stats.samples_navigated_backwards)
    return (
        f"wrote {len(nav)} rows to {out}{steps} ({rec.format} recording, profile {profile or rec.profile}{skipped})"
        f"{handled}{gait}"
    )


@dataclass(frozen=True)
class ExportJob:
    """``footnav export`` of one file of a folder (``footnav.app.commands.batch``): called with a source, it writes
    its track to ``destinations[source]`` (creating the folder) with these options, as :func:`run_export` does."""

    destinations: dict[Path, Path]
    fmt: str | None = None
    columns: str | None = None
    profile: str | None = None
    smooth: str | None = None
    stance_levels: bool = True
    out_format: str | None = None

    def __call__(self, source: Path) -> str:
        out = self.destinations[source]
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FootnavError(f"cannot create {out.parent}: {exc.strerror}") from None
        return run_export(
            source,
            out,
            fmt=self.fmt,
            columns=self.columns,
            profile=self.profile,
            smooth=self.smooth,
            stance_levels=self.stance_levels,
            out_format=self.out_format,
        )


def export_files(
    paths: list[Path],
    out_dir: Path,
    jobs: int | None = None,
    client: Client | None = None,
    **options: str | bool | None,
) -> list[FileResult[str]]:
    """Export every recording (and capture) found in ``paths`` to ``out_dir`` (``<stem>.csv``, or ``.parquet`` with
    ``out_format="parquet"``, below the subfolders it had) on ``jobs`` processes or ``client``'s Dask cluster
    (``footnav.app.commands.batch.run_files``); ``options`` as :class:`ExportJob`'s. Returns each file's result (its
    summary line, or its failure), in the order of the files.

    Raises
    ------
    FootnavError
        nothing found, ``out_dir`` is a file, or two files would write the same track.
    """
    from footnav.app.commands.batch import export_destinations, find_export_inputs, run_files

    files = find_export_inputs(paths)
    if not files:
        raise FootnavError("no recordings found in " + ", ".join(str(p) for p in paths))
    if out_dir.exists() and not out_dir.is_dir():
        raise FootnavError(f"{out_dir} is a file; with a folder or several recordings, -o names a folder")
    out_format = str(options.get("out_format") or "csv")
    if out_format == "parquet":
        require_pyarrow()  # once, before any file is navigated
    suffix = TRACK_FORMATS[out_format]
    dests = export_destinations(paths, files, out_dir, suffix)
    job = ExportJob(dict(zip(files, dests, strict=True)), **options)  # type: ignore[arg-type]
    return run_files(job, files, jobs, "export", client=client)


def run_export_batch(
    paths: list[Path],
    out_dir: Path,
    jobs: int | None = None,
    client: Client | None = None,
    **options: str | bool | None,
) -> tuple[list[str], list[str]]:
    """:func:`export_files`, as each file's summary line and each failure's, in the order of the files."""
    results = export_files(paths, out_dir, jobs, client, **options)
    return [r.value for r in results if r.value is not None], [r.error for r in results if r.error]


def load_other_recording(path: Path, fmt: str | None, columns: str | None) -> Recording:
    """A recording from another tool (``--format``, ``--columns`` as the commands take them).

    Raises
    ------
    InputFormatError
        not a recording footnav reads; a file of no known kind is told footnav's captures too
        (``export`` and ``replay`` take them).
    """
    try:
        return load_recording(path, fmt, CsvMapping.parse(columns) if columns else None)
    except InputFormatError as exc:
        if "unknown recording format" not in str(exc):
            raise
        raise InputFormatError(f"{exc}; or a footnav capture (.mcap)") from None


def _build_csv_kernels(build_writer: Callable[[], None] | None) -> None:
    """A first run's share beside the detector's kernels: the CSV reader's (the next CSV read uses it; this one was
    read by ``np.loadtxt``) and ``build_writer``'s."""
    build_reader_kernel()
    if build_writer is not None:
        build_writer()


def export_capture(
    source: Path,
    out: Path,
    steps_out: Path | None = None,
    *,
    smooth: str | None = None,
    gait_out: Path | None = None,
    out_format: str | None = None,
) -> str:
    """Replay a footnav capture headless and write each foot's rows (``out`` for one foot, else
    ``<stem>-<foot><suffix>`` beside it) and, with ``steps_out``, its steps (named alike); returns a
    one-line summary. ``smooth`` (one of ``SMOOTHING``): the session smoothed instead
    (``footnav.app.commands.smooth_capture``; refused for ToF units).

    Raises
    ------
    KeyboardInterrupt
        the replay was interrupted (Ctrl-C): nothing written.
    """
    if steps_out is not None or gait_out is not None:
        _check_samples_captured(source)
    if smooth:
        from footnav.app.commands.smooth_capture import smooth_capture

        navs = {foot: nav for foot, (nav, _) in smooth_capture(source, smooth).items()}
        how = "RTS-smoothed" if smooth == "whole" else "smoothed step by step"
    else:
        navs = _replayed_capture(source)
        how = "replayed"
    if not navs:
        raise FootnavError(f"{source}: the capture never stood still long enough to align; nothing written")
    written, gait = [], []
    for foot, nav in navs.items():
        path = out if len(navs) == 1 else foot_path(out, foot)
        write_track(nav, path, out_format)
        written.append(f"{len(nav)} rows to {path}{' with clearance' if nav.floor_z_m is not None else ''}")
        if steps_out is not None:
            spath = steps_out if len(navs) == 1 else foot_path(steps_out, foot)
            written.append(write_steps_csv(nav, spath, with_covariance=not smooth))
        if gait_out is not None:
            from footnav.app.api.gait_export import export_gait

            gpath = gait_out if len(navs) == 1 else foot_path(gait_out, foot)
            label = f" {foot}" if len(navs) > 1 else ""
            gait.append(export_gait(nav, gpath, causal_from=None if smooth else 0, label=label))
    return f"wrote {'; '.join(written)} (footnav capture, {how})" + "".join(f"\n{g}" for g in gait)


def _check_samples_captured(source: Path) -> None:
    """``--steps`` and ``--gait`` find the steps in a navigated walk; a unit's stepwise output has none to find.

    Raises
    ------
    FootnavError
        a foot of the capture sent the unit's own steps.
    """
    from footnav.app.commands.replay import ReplayOptions, checked_summary, onboard_outputs
    from footnav.app.config import defaults

    summary = checked_summary(ReplayOptions(path=source, config=defaults(), viewer=False))
    if "steps" in onboard_outputs(summary).values():
        raise FootnavError(
            f"{source} holds the unit's own steps (stepwise dead reckoning), not its samples: --steps and --gait "
            "find the steps of a navigated walk; the track file alone has one row per step"
        )


def foot_path(path: Path, foot: str) -> Path:
    """``<stem>-<foot><suffix>`` beside ``path``: one foot's file of two (a two-feet capture's export, or
    ``export --left --right``)."""
    return path.with_name(f"{path.stem}-{foot}{path.suffix}")


def _replayed_capture(source: Path) -> dict[str, NavBatch]:
    """Each foot's live estimates, replayed headless (feet that never aligned left out)."""
    from footnav.app.commands.replay import ReplayOptions, run_replay
    from footnav.app.config import defaults
    from footnav.pipeline.nav_types import concat_batches

    got: dict[str, list[NavBatch]] = {}

    def collect(foot: str) -> Callable[[NavBatch], None]:
        return got.setdefault(foot, []).append

    code = run_replay(ReplayOptions(path=source, config=defaults(), viewer=False, collect=collect, quiet=True))
    if code == 130:
        raise KeyboardInterrupt
    if code != 0:
        raise FootnavError(f"{source}: the replay failed; nothing written")
    # a lead-in filled in comes after the estimates it precedes (``footnav.app.session.run_unit_session``)
    return {foot: concat_batches(sorted(b, key=lambda n: float(n.t_s[0]))) for foot, b in got.items() if b}
