"""The dual-IMU board in Rerun: each IMU's track, the fused tracks, truth, constraint residuals.

:func:`save_dual_runs` writes one or more runs (e.g. the two courses of ``footnav experiment
dual-imu``) to an ``.rrd`` file with its blueprint: one 3D view per run (tracks) and one
time-series view per residual. Tracks are decimated for the file (every ``track_every``-th sample);
residuals keep every sample where they were formed (NaN rows, where a constraint was not applied,
are left out).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from footnav.views.convert import time_column
from footnav.views.paths import TIMELINE, DualPaths
from numpy.typing import NDArray

F64 = NDArray[np.float64]

AXES = ("x", "y", "z")
TRACK_RADIUS_M = 0.01
METHOD_COLORS: dict[str, tuple[int, int, int]] = {
    "single": (230, 80, 60),
    "classic": (200, 160, 0),
    "paper": (160, 90, 220),
    "paper-3c": (220, 160, 250),
    "footnav": (0, 200, 120),
    "imu1": (0, 160, 255),
    "imu2": (255, 140, 0),
    "truth": (150, 150, 150),
}


@dataclass(frozen=True, slots=True)
class DualRunView:
    """What is shown of one dual-IMU run.

    Attributes
    ----------
    t_s
        (n,) sample times, s.
    truth_n_m
        (n, 3) IMU 1's true position, m, or None (a live session logs truth its own way).
    tracks_n_m
        method -> (n, 3) IMU 1's position as the method estimates it (NaN rows skipped).
    imu_tracks_n_m
        IMU name -> (n, 3) that IMU's own track.
    residuals
        residual name (with its unit) -> (n, 3) values, NaN where not formed.
    """

    t_s: F64
    truth_n_m: F64 | None
    tracks_n_m: Mapping[str, F64]
    imu_tracks_n_m: Mapping[str, F64]
    residuals: Mapping[str, F64]


def _points(entity: str, t_s: F64, pos: F64, every: int) -> tuple[str, rr.TimeColumn, rr.ComponentColumnList] | None:
    """Every ``every``-th finite row of ``pos`` as a Points3D column (colours: :func:`static_styles`)."""
    keep = np.zeros(t_s.shape[0], dtype=bool)
    keep[::every] = True
    keep &= np.all(np.isfinite(pos), axis=1)
    if not keep.any():
        return None
    return entity, time_column(t_s[keep]), rr.Points3D.columns(positions=pos[keep].astype(np.float32))


def dual_columns(
    view: DualRunView, paths: DualPaths, *, track_every: int = 10
) -> list[tuple[str, rr.TimeColumn, rr.ComponentColumnList]]:
    """``(entity, index, columns)`` triples for ``send_columns``."""
    out = []
    items = [] if view.truth_n_m is None else [(paths.truth, view.truth_n_m)]
    items += [(paths.track(m), p) for m, p in view.tracks_n_m.items()]
    items += [(paths.imu(i), p) for i, p in view.imu_tracks_n_m.items()]
    for entity, pos in items:
        col = _points(entity, view.t_s, pos, track_every)
        if col is not None:
            out.append(col)
    for name, values in view.residuals.items():
        formed = np.all(np.isfinite(values), axis=1)
        if not formed.any():
            continue
        index = time_column(view.t_s[formed])
        for a, axis in enumerate(AXES):
            out.append((paths.residual(name, axis), index, rr.Scalars.columns(scalars=values[formed, a])))
    return out


def static_styles(view: DualRunView, paths: DualPaths) -> list[tuple[str, rr.AsComponents]]:
    """Colours and radii of the tracks, logged once."""
    out: list[tuple[str, rr.AsComponents]] = []
    if view.truth_n_m is not None:
        out.append((paths.truth, rr.Points3D.from_fields(colors=[METHOD_COLORS["truth"]], radii=[TRACK_RADIUS_M])))
    for m in view.tracks_n_m:
        out.append(
            (
                paths.track(m),
                rr.Points3D.from_fields(colors=[METHOD_COLORS.get(m, (200, 200, 200))], radii=[TRACK_RADIUS_M]),
            )
        )
    for i in view.imu_tracks_n_m:
        out.append(
            (
                paths.imu(i),
                rr.Points3D.from_fields(colors=[METHOD_COLORS.get(i, (200, 200, 200))], radii=[TRACK_RADIUS_M]),
            )
        )
    return out


def dual_blueprint(runs: Mapping[str, DualRunView]) -> rrb.Blueprint:
    """Per run: a 3D view of the tracks beside time-series views of its residuals."""
    trail = rrb.VisibleTimeRanges(
        timeline=TIMELINE, start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.cursor_relative()
    )
    rows = []
    for run, view in runs.items():
        paths = DualPaths(run)
        plots = [rrb.TimeSeriesView(origin=f"{paths.plots}/{name}", name=f"{run}: {name}") for name in view.residuals]
        rows.append(
            rrb.Horizontal(
                rrb.Spatial3DView(origin=paths.root, name=f"{run}: tracks", time_ranges=trail),
                rrb.Vertical(*plots),
            )
        )
    return rrb.Blueprint(rrb.Vertical(*rows), collapse_panels=True)


def save_dual_runs(
    path: Path | str, runs: Mapping[str, DualRunView], *, track_every: int = 10, application_id: str = "footnav"
) -> None:
    """Write ``runs`` (run name -> view) with the blueprint to the ``.rrd`` file ``path``."""
    rec = rr.RecordingStream(application_id)
    rec.save(str(path), default_blueprint=dual_blueprint(runs))
    try:
        for run, view in runs.items():
            paths = DualPaths(run)
            for entity, archetype in static_styles(view, paths):
                rec.log(entity, archetype, static=True)
            for entity, index, columns in dual_columns(view, paths, track_every=track_every):
                rec.send_columns(entity, indexes=[index], columns=columns)
    finally:
        rec.flush()
        rec.disconnect()
