"""The viewer's stride table: per foot, each stride between consecutive footfalls (step onsets, as
``NavBatch.step_onsets`` marks them) with its length, duration, speed and peak clearance, the gait
parameters of ``footnav.pipeline.gait.parameters`` (there the length runs between the stances' middles;
live, at the footfall that ends a stride, between the footfalls), the last :data:`SHOWN_STRIDES` of them
and the means of all, as a Markdown document. An onset within ``MIN_STRIDE_S`` of the last footfall
belongs to the same stance; a stride over ``MAX_STRIDE_S`` (a pause) or of under 5 cm is no stride.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from footnav.pipeline.gait.parameters import MAX_STRIDE_S, MIN_STRIDE_S, stride_parameters
from footnav.pipeline.nav_types import NavBatch
from numpy.typing import NDArray

SHOWN_STRIDES = 8
_Samples = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_], NDArray[np.float64]]
"""Times, positions, attitudes, stance flags and clearances of consecutive samples."""


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
    since: list[_Samples] = field(default_factory=list)
    """The samples from the last footfall on, while ``open``."""
    open: bool = False
    """A stride runs from the last footfall (not once it spans more than ``MAX_STRIDE_S``)."""
    latest_t_s: float = -np.inf
    """The time of the latest sample taken, s."""


class StrideTable:
    """Strides of the feet, fed with each foot's batches in order (``update``)."""

    def __init__(self, feet: tuple[str, ...]) -> None:
        self._feet = {f: _Foot() for f in feet}

    def update(self, foot: str, nav: NavBatch) -> bool:
        """Take a batch (its ``step_onsets`` filled); True when it ended a stride. A batch that ends before
        the latest sample taken (a lead-in filled in: ``footnav.pipeline.navigation.lead_in``) adds its own
        strides before the others."""
        state = self._feet[foot]
        if len(nav) and float(nav.t_s[-1]) < state.latest_t_s:
            earlier = _Foot()
            added = self._take(earlier, nav)
            state.strides[:0] = earlier.strides
            return added
        if len(nav):
            state.latest_t_s = float(nav.t_s[-1])
        return self._take(state, nav)

    @classmethod
    def _take(cls, state: _Foot, nav: NavBatch) -> bool:
        """The batch's footfalls and samples into ``state``; True when it ended a stride."""
        onsets = nav.step_onsets if nav.step_onsets is not None else np.zeros(0, dtype=np.intp)
        start = 0
        added = False
        for k in onsets.tolist():
            t = float(nav.t_s[k])
            if state.last_t_s is not None and t - state.last_t_s < MIN_STRIDE_S:
                continue
            if state.open:
                added |= cls._add_stride(state, [*state.since, _samples(nav, start, k + 1)])
            state.last_t_s, state.since, state.open, start = t, [], True, k
        if state.open and state.last_t_s is not None:
            state.since.append(_samples(nav, start, len(nav)))
            if float(nav.t_s[-1]) - state.last_t_s > MAX_STRIDE_S:
                state.since, state.open = [], False  # a pause: the next footfall starts the next stride
        return added

    @staticmethod
    def _add_stride(state: _Foot, parts: list[_Samples]) -> bool:
        """The stride of the samples, from the first (a footfall) to the last (the next)."""
        t, pos, quat, stance, clearance = (np.concatenate(arrays) for arrays in zip(*parts, strict=True))
        falls = np.array([0, t.size - 1], dtype=np.intp)
        s = stride_parameters(t, pos, quat, stance, clearance, falls=falls, at="footfall")
        if not len(s):
            return False
        state.strides.append(
            Stride(float(s.end_s[0]), float(s.length_m[0]), float(s.duration_s[0]), float(s.max_clearance_m[0]))
        )
        return True

    def strides(self, foot: str) -> list[Stride]:
        """The strides of ``foot`` so far, in time order (the list itself: do not change it)."""
        return self._feet[foot].strides

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


def _samples(nav: NavBatch, a: int, b: int) -> _Samples:
    """Samples [a, b) of ``nav``: the arrays of a stride's parameters."""
    return (nav.t_s[a:b], nav.pos_n_m[a:b], nav.quat_nb_wxyz[a:b], nav.stance[a:b], nav.clearance_m[a:b])


def _row(label: str, s: Stride) -> str:
    return f"| {label} | {s.length_m:.2f} | {s.duration_s:.2f} | {s.speed_mps:.2f} | {s.peak_m:.3f} |"
