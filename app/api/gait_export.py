"""``footnav export --gait FILE.csv``: one row per stride of the gait parameters, and the recording's summary.

The parameters and their definitions are ``footnav.pipeline.gait.parameters``; the columns are
:data:`GAIT_COLUMNS`, SI units as their names say (``_share``: a fraction, ``_spm``: steps per minute), an
empty cell where a stride has no value. :func:`summary_line` is the line ``footnav export`` prints: each
parameter's mean ± SD over the strides and its coefficient of variation (SD / mean).
"""

from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path

from footnav.app.commands.export import _write_csv
from footnav.pipeline.gait.parameters import SUMMARIZED, StrideParameters, gait_parameters, summarize
from footnav.pipeline.nav_types import NavBatch

GAIT_COLUMNS = tuple(f.name for f in fields(StrideParameters))
"""The columns of ``--gait``: the attributes of ``StrideParameters``, in order."""

_INTEGER = {"start_index", "toe_off_index", "end_index"}

_SHOWN: dict[str, tuple[str, str, float, int]] = {
    "length_m": ("length", "m", 1.0, 3),
    "duration_s": ("duration", "s", 1.0, 3),
    "cadence_spm": ("cadence", "steps/min", 1.0, 1),
    "speed_mps": ("speed", "m/s", 1.0, 3),
    "stance_s": ("stance", "s", 1.0, 3),
    "swing_s": ("swing", "s", 1.0, 3),
    "stance_share": ("stance share", "%", 100.0, 1),
    "swing_share": ("swing share", "%", 100.0, 1),
    "turning_rad": ("turning", "rad", 1.0, 3),
    "lateral_m": ("lateral deviation", "m", 1.0, 3),
    "max_clearance_m": ("max clearance", "m", 1.0, 3),
    "min_clearance_m": ("mid-swing min clearance", "m", 1.0, 3),
}
"""How :func:`summary_line` shows each of ``SUMMARIZED``: words, unit, scale, decimals."""
assert tuple(_SHOWN) == SUMMARIZED


def write_gait_csv(strides: StrideParameters, path: Path) -> None:
    """Write :data:`GAIT_COLUMNS`, one row per stride, to ``path``.

    Raises
    ------
    FootnavError
        the file cannot be written.
    """
    table = strides.columns()
    rows = (
        [int(table[name][k]) if name in _INTEGER else _cell(float(table[name][k])) for name in GAIT_COLUMNS]
        for k in range(len(strides))
    )
    _write_csv(path, GAIT_COLUMNS, rows)


def _cell(value: float) -> str:
    return "" if math.isnan(value) else f"{value:.9g}"


def summary_line(strides: StrideParameters, label: str = "") -> str:
    """The recording's gait in one line: "gait[ label] (mean ± SD, CV): N strides; length 1.352 ± 0.026 m,
    1.9 %; ..." (a parameter without two values is left out)."""
    if len(strides) < 2:
        return f"gait{label}: {len(strides)} stride{'' if len(strides) == 1 else 's'}, too few for a summary"
    parts = []
    for name, s in summarize(strides).items():
        if math.isnan(s.sd):
            continue
        words, unit, scale, decimals = _SHOWN[name]
        cv = "" if math.isnan(s.cv) else f", {100.0 * s.cv:.1f} %"
        parts.append(f"{words} {scale * s.mean:.{decimals}f} ± {scale * s.sd:.{decimals}f} {unit}{cv}")
    return f"gait{label} (mean ± SD, CV): {len(strides)} strides; {'; '.join(parts)}"


def export_gait(nav: NavBatch, path: Path, *, causal_from: int | None, label: str = "") -> str:
    """The gait parameters of ``nav`` written to ``path`` (``causal_from``: as for
    ``footnav.pipeline.gait.parameters.gait_parameters``); returns the summary line."""
    strides = gait_parameters(nav, causal_from=causal_from)
    write_gait_csv(strides, path)
    return f"{summary_line(strides, label)} (to {path})"
