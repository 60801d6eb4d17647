"""The viewer's stride table: per foot, each stride between consecutive footfalls (step onsets, as
``NavBatch.step_onsets`` marks them) with its length (horizontal distance between the two
footfalls), duration, speed (length / duration) and peak clearance (largest ``clearance_m`` between
them), the last :data:`SHOWN_STRIDES` of them and the means of all, as a Markdown document. An onset
within :data:`MIN_STRIDE_S` of the last footfall belongs to the same stance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from footnav.pipeline.nav_types import NavBatch

SHOWN_STRIDES = 8
MIN_STRIDE_S = 0.25
"""A footfall this soon after the last one is the detector's flicker within one stance, not a stride
(running strides last about 0.6 s and more)."""


@dataclass(frozen=True, slots=True)
class Stride:
    """One stride: ``t_s`` its end (the second footfall), s; ``length_m``; ``duration_s``; ``peak_m``."""

    t_s: float
    length_m: float
    duration_s: float
    peak_m: float

    @property
    def speed_mps(self) -> float:
        return self.length_m / self.duration_s if self.duration_s > 0 else float("nan")


@dataclass(slots=True)
class _Foot:
    strides: list[Stride] = field(default_factory=list)
    last_t_s: float | None = None
    last_xy_m: tuple[float, float] = (0.0, 0.0)
    peak_m: float = float("-inf")


class StrideTable:
    """Strides of the feet, fed with each foot's batches in order (``update``)."""

    def __init__(self, feet: tuple[str, ...]) -> None:
        self._feet = {f: _Foot() for f in feet}

    def update(self, foot: str, nav: NavBatch) -> bool:
        """Take a batch (its ``step_onsets`` filled); True when it ended a stride."""
        state = self._feet[foot]
        onsets = nav.step_onsets if nav.step_onsets is not None else np.zeros(0, dtype=np.intp)
        start = 0
        added = False
        for k in (*onsets.tolist(), len(nav)):
            if k > start:
                state.peak_m = max(state.peak_m, float(np.nanmax(nav.clearance_m[start:k], initial=-np.inf)))
            if k == len(nav):
                break
            t, xy = float(nav.t_s[k]), (float(nav.pos_n_m[k, 0]), float(nav.pos_n_m[k, 1]))
            if state.last_t_s is not None and t - state.last_t_s < MIN_STRIDE_S:
                continue
            if state.last_t_s is not None:
                length = float(np.hypot(xy[0] - state.last_xy_m[0], xy[1] - state.last_xy_m[1]))
                state.strides.append(Stride(t, length, t - state.last_t_s, state.peak_m))
                added = True
            state.last_t_s, state.last_xy_m, state.peak_m = t, xy, float("-inf")
            start = k
        return added

    def markdown(self) -> str:
        """The table of every foot: its last strides and the means of all of them."""
        parts = []
        for foot, state in self._feet.items():
            rows = state.strides
            if not rows:
                continue
            head = (
                f"**{foot}**: {len(rows)} strides" if len(self._feet) > 1 or foot != "foot" else f"{len(rows)} strides"
            )
            lines = [
                head,
                "",
                "| end [s] | length [m] | duration [s] | speed [m/s] | peak clearance [m] |",
                "|---|---|---|---|---|",
            ]
            lines += [_row(f"{s.t_s:.1f}", s) for s in rows[-SHOWN_STRIDES:]]
            mean = Stride(
                float("nan"),
                float(np.mean([s.length_m for s in rows])),
                float(np.mean([s.duration_s for s in rows])),
                float(np.mean([s.peak_m for s in rows])),
            )
            lines.append(_row("**mean**", mean))
            parts.append("\n".join(lines))
        return "\n\n".join(parts) if parts else "No stride yet: a stride ends at the second footfall."


def _row(label: str, s: Stride) -> str:
    return f"| {label} | {s.length_m:.2f} | {s.duration_s:.2f} | {s.speed_mps:.2f} | {s.peak_m:.3f} |"
