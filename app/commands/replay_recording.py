"""``footnav replay RECORDING``: a recording from another tool navigated and shown in Rerun.

The recording (PyShoe ``.mat``, x-io CSV, OpenShoe log, generic CSV, a unit's raw log:
``footnav.device.files.recordings``)
is navigated whole, exactly as ``footnav export`` navigates it (``navigate_recording``: the causal
filter, or a smoother with ``smooth``), and its track goes to the same Rerun views as a live session's;
with ``smooth`` the smoothed track is drawn beside the causal filter's (as a live session draws its
step-smoothed track).
Where the recording has ground truth (the PyShoe VICON trials), the truth is shown too, turned and
moved onto the estimate by the least-squares yaw and translation fit that ``footnav evaluate`` uses
(``footnav.pipeline.metrics.ate``).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from footnav.app.commands.export import load_other_recording, navigate_recording
from footnav.app.feet import check_lsl, close_lsl_outlets, notice, open_lsl_outlets
from footnav.app.status import input_handling, lead_in_note
from footnav.device.files.recordings import Recording
from footnav.pipeline.gait.events import GaitEventTracker
from footnav.pipeline.metrics import ate, path_length_m
from footnav.pipeline.nav_types import NavBatch, SmoothedSpan
from footnav.views.lsl import LslRequest, lsl_feet
from footnav.views.outputs import SessionViews, open_session_views
from numpy.typing import NDArray

PUT_TIMEOUT_S = 60.0
"""How long a batch may wait for room in a Rerun logger's queue (a file is written as fast as it can)."""


@dataclass(frozen=True)
class RecordingReplayOptions:
    """What ``footnav replay`` was asked for, for a recording from another tool.

    Attributes
    ----------
    fmt, columns
        the recording's format (None: detected) and, for a generic CSV, its column mapping
        (``CsvMapping.parse`` grammar).
    profile
        the unit profile (None: the format's sensor).
    smooth
        None (causal), ``whole`` or ``step`` (``footnav.app.commands.export.SMOOTHING``).
    lsl
        ``--lsl``: the estimates on Lab Streaming Layer too (:mod:`footnav.views.lsl`), all at once
        once navigated, as from a unit ``replay:<recording name>``; with ``smooth``, the smoothed track.
    """

    path: Path
    fmt: str | None = None
    columns: str | None = None
    profile: str | None = None
    smooth: str | None = None
    stance_levels: bool = True
    save: Path | None = None
    viewer: bool = True
    web: bool = False
    keep_web: bool = False
    lsl: LslRequest | None = None


def truth_on_estimate(est_pos_m: NDArray[np.float64], gt_pos_m: NDArray[np.float64]) -> NDArray[np.float64]:
    """(n, 3) ground truth turned about z and moved onto the (n, 3) estimate by the fit of
    :func:`footnav.pipeline.metrics.ate` (mirrored back when the fit mirrored the estimate)."""
    fit = ate(est_pos_m, gt_pos_m, mirror_test=True)
    est = est_pos_m * np.array([1.0, -1.0, 1.0]) if fit.mirrored else est_pos_m
    c, s = math.cos(fit.yaw_rad), math.sin(fit.yaw_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    # the fit maps est to gt: gt ≈ (est − mean est) Rᵀ + mean gt; its inverse maps gt onto est
    truth = (gt_pos_m - gt_pos_m.mean(axis=0)) @ rot + est.mean(axis=0)
    return truth * np.array([1.0, -1.0, 1.0]) if fit.mirrored else truth


def run_recording_replay(opts: RecordingReplayOptions) -> int:
    """Navigate the recording and show it; returns the exit code.

    Raises
    ------
    InputFormatError
        the file is not a recording footnav reads (the message names what was expected).
    FootnavError
        the recording never stands still, so it cannot be aligned.
    """
    rec = load_other_recording(opts.path, opts.fmt, opts.columns)
    how = {
        None: "causal filter",
        "whole": "RTS-smoothed, drawn in purple beside the causal filter's track",
        "step": "smoothed step by step, drawn in purple beside the causal filter's track",
    }[opts.smooth]
    print(
        f"replaying {opts.path} ({rec.format} recording, {len(rec)} samples at {rec.rate_hz:.0f} Hz, "
        f"profile {opts.profile or rec.profile}, {how})",
        file=sys.stderr,
    )
    nav, stats = navigate_recording(rec, opts.profile, opts.smooth, opts.stance_levels)
    shown = GaitEventTracker().annotate(nav if opts.smooth is None else beside_causal(rec, nav, opts))
    lsl_streams = lsl_feet(
        opts.lsl, {"foot": f"replay:{rec.name}"}, units=f"{rec.format} recording", rates={"foot": rec.rate_hz}
    )
    check_lsl(lsl_streams)  # pylsl missing: stop before the viewer starts
    views, notes = open_session_views(
        save=opts.save,
        want_viewer=opts.viewer,
        web=opts.web,
        keep_web=opts.keep_web,
        recording_id=f"replay-{rec.name}",
        notice=notice,
        truth=rec.gt_pos_m is not None,
    )
    for note in notes:
        print(note, file=sys.stderr)
    if views is not None:
        _show(views, rec, shown, stats.samples_before_alignment - stats.samples_navigated_backwards)
        for note in views.close():
            notice(note)
    lsl = None
    try:
        lsl = open_lsl_outlets(
            lsl_streams,
            wait_s=opts.lsl.wait_s if opts.lsl else 0.0,
            max_buffered_s=math.ceil(len(nav) / rec.rate_hz) + 60,  # all of it is pushed at once
        )
        if lsl is not None:  # the track asked for: with smooth, the smoothed one (not the causal one drawn beside it)
            lsl.put(shown if opts.smooth is None else GaitEventTracker().annotate(nav), foot="foot")
    finally:
        close_lsl_outlets(lsl)
    handled = f"; {h}" if (h := input_handling(stats)) else ""
    print(
        f"samples navigated: {len(nav)} of {len(rec)}"
        + (f" ({lead_in_note(stats).removeprefix(', ')})" if stats.samples_before_alignment else "")
        + f"; distance {path_length_m(nav.pos_n_m[:: max(1, round(rec.rate_hz / 20))]):.2f} m{handled}"
    )
    return 0


def beside_causal(rec: Recording, smoothed: NavBatch, opts: RecordingReplayOptions) -> NavBatch:
    """The causal filter's estimates of the recording with the smoothed ones attached
    (``NavBatch.smoothed``), so that the views draw both tracks."""
    causal, _ = navigate_recording(rec, opts.profile, None, opts.stance_levels)
    if len(causal) != len(smoothed):  # both navigate every sample; keep the smoothed alone otherwise
        return smoothed
    span = SmoothedSpan(
        first_sample=0,
        t_s=smoothed.t_s,
        pos_n_m=smoothed.pos_n_m,
        vel_n_mps=smoothed.vel_n_mps,
        quat_nb_wxyz=smoothed.quat_nb_wxyz,
        clearance_m=smoothed.clearance_m,
    )
    return dataclasses.replace(causal, smoothed=span)


def _show(views: SessionViews, rec: Recording, nav: NavBatch, skipped: int) -> None:
    """The track (its gait events filled), the aligned truth (if any) and the recording's notes on every view."""
    if rec.gt_pos_m is not None:
        gt = rec.gt_pos_m[skipped:] - rec.gt_pos_m[skipped]
        views.log_truth(truth_on_estimate(nav.pos_n_m, gt), t_s=nav.t_s)
    views.log_event(f"{rec.format} recording {rec.name}: {len(rec)} samples at {rec.rate_hz:.0f} Hz", t_s=0.0)
    for note in rec.notes:
        views.log_event(note, t_s=0.0)
    views.put(nav, timeout_s=PUT_TIMEOUT_S)
