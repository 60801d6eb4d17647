"""``footnav export``: a recording -> one CSV row per sample of the navigation solution."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from pipeline.errors import FootnavError
from pipeline.loaders import CsvMapping, Recording, load_recording
from pipeline.nav_types import NavBatch
from pipeline.navigator import NavConfig, NavStats, navigate
from pipeline.profiles import get_profile
from pipeline.saturation import reconstruct_saturated_rates

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


def navigate_recording(
    rec: Recording, profile: str | None = None, smooth: bool = False
) -> tuple[NavBatch, NavStats]:
    """Run the navigator (and the smoother when asked) over a whole recording.

    The gyroscope's saturated stretches are reconstructed first (``pipeline.saturation``: this needs
    the whole recording, so it happens here and not in the live navigator).

    Raises:
        FootnavError: the recording never stands still, so it cannot be aligned.
    """
    config = NavConfig(profile=get_profile(profile or rec.profile))
    gyr, _ = reconstruct_saturated_rates(rec.t_s, rec.gyr_b_radps)
    if smooth:
        from pipeline.smoother import smooth_recording

        nav, stats = smooth_recording(rec.t_s, rec.acc_b_mps2, gyr, rec.rate_hz, config)
    else:
        nav, stats = navigate(rec.t_s, rec.acc_b_mps2, gyr, rec.rate_hz, config)
    if nav is None:
        raise FootnavError(
            f"{rec.name}: the unit is never still for {config.align_s:.1f} s, so roll and pitch cannot be "
            "aligned; a recording must start (or at least include) a moment of standing still"
        )
    return nav, stats


def write_track_csv(nav: NavBatch, path: Path) -> None:
    """Write ``EXPORT_COLUMNS``: SI units, navigation frame right-handed z up, origin at the start."""
    var = np.diagonal(nav.pos_cov_n_m2, axis1=1, axis2=2)
    table = np.column_stack(
        [nav.t_s, nav.pos_n_m, nav.vel_n_mps, nav.quat_nb_wxyz, nav.stance.astype(np.float64), var]
    )
    try:
        with path.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(EXPORT_COLUMNS)
            stance_col = EXPORT_COLUMNS.index("stance")
            for row in table:
                writer.writerow([int(v) if i == stance_col else f"{v:.9g}" for i, v in enumerate(row)])
    except OSError as exc:
        raise FootnavError(f"cannot write {path}: {exc.strerror}") from None


def run_export(
    source: Path, out: Path, *, fmt: str | None, columns: str | None, profile: str | None, smooth: bool
) -> str:
    """Load, navigate and write; returns a one-line summary."""
    rec = load_recording(source, fmt, CsvMapping.parse(columns) if columns else None)
    nav, stats = navigate_recording(rec, profile, smooth)
    write_track_csv(nav, out)
    skipped = (
        f", {stats.samples_before_alignment} samples before the first still period not navigated"
        if stats.samples_before_alignment
        else ""
    )
    return (
        f"wrote {len(nav)} rows to {out} ({rec.format} recording, profile {profile or rec.profile}{skipped})"
    )
