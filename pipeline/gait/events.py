"""Per-foot gait events of a navigation stream: where each step lands, and the whole-swing clearance.

A step lands at the first stance sample after a swing; the still stance a session starts in is the
start, not a step. For ToF units the swing-complete clearance
(:class:`footnav.pipeline.gait.tof_clearance.SwingClearanceTracker`) is added as each swing's
samples become final, with the session's ``TofConfig.snap_m``. :class:`GaitEventTracker` fills
``NavBatch.step_onsets`` and ``NavBatch.swing_clearance`` so that the views only convert.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np
from footnav.pipeline.gait.tof_clearance import SwingClearanceTracker
from footnav.pipeline.nav_types import ClearanceSeries, NavBatch
from numpy.typing import NDArray


def step_onsets(stance: NDArray[np.bool_], previous: bool | None) -> NDArray[np.intp]:
    """Indices where a step lands: stance after swing.

    Parameters
    ----------
    stance
        (n,) zero-velocity flags of consecutive samples.
    previous
        The flag of the sample before ``stance[0]``; None at the start of a session, where standing
        still is the start, not a step.

    Returns
    -------
    numpy.ndarray
        (k,) indices into ``stance``.
    """
    s = np.asarray(stance, dtype=bool)
    if s.size == 0:
        return np.zeros(0, dtype=np.intp)
    before = np.empty(s.shape, dtype=bool)
    before[0] = True if previous is None else previous
    before[1:] = s[:-1]
    return np.flatnonzero(s & ~before)


class GaitEventTracker:
    """Fills the gait events of one foot's batches, fed in order.

    Parameters
    ----------
    tof_snap_m
        ``TofConfig.snap_m`` of the session (hits within this height are one surface), m; the
        whole-swing clearance is tracked once a batch carries a ToF floor (``NavBatch.floor_z_m``).
    """

    def __init__(self, tof_snap_m: float | None = None) -> None:
        self._snap_m = tof_snap_m
        self._last_stance: bool | None = None
        self._swing: SwingClearanceTracker | None = None

    def annotate(self, nav: NavBatch) -> NavBatch:
        """``nav`` with ``step_onsets`` (unless it has them: a unit's stepwise output) and, for ToF units,
        ``swing_clearance`` filled in."""
        if len(nav) == 0:
            return nav
        onsets = nav.step_onsets if nav.step_onsets is not None else step_onsets(nav.stance, self._last_stance)
        self._last_stance = bool(nav.stance[-1])
        swing = None
        if self._swing is None and nav.floor_z_m is not None and self._snap_m is not None:
            self._swing = SwingClearanceTracker(self._snap_m)
        if self._swing is not None:
            swing = ClearanceSeries(*self._swing.update(nav.t_s, nav.pos_n_m, nav.stance, nav.clearance_m, nav.ranges))
        return dataclasses.replace(nav, step_onsets=onsets, swing_clearance=swing)

    def finish(self) -> ClearanceSeries | None:
        """The whole-swing clearance of the samples still held (a swing still open is looked up with
        the hits there are); None when no ToF floor was seen."""
        if self._swing is None:
            return None
        return ClearanceSeries(*self._swing.finish())

    def feeding(self, sinks: Sequence[Callable[[NavBatch], object]]) -> Callable[[NavBatch], None]:
        """One sink that annotates each batch once, then hands it to every one of ``sinks`` in order."""

        def annotate_then_send(nav: NavBatch) -> None:
            annotated = self.annotate(nav)
            for sink in sinks:
                sink(annotated)

        return annotate_then_send
