"""A left and a right recording navigated as one problem: :func:`navigate_pair`.

The two recordings are put on one clock by their time stamps (each file's own clock,
``Recording.t_start_s`` plus its sample times; both files must come from one clock, e.g. one logger or
synchronised units), their saturated gyroscope stretches are reconstructed as for one foot
(``footnav.pipeline.navigation.saturation``), and ``footnav.pipeline.two_feet.navigate_feet`` runs their
navigators in lockstep, coupled by the inter-foot distance bound (``footnav.pipeline.two_feet.separation``)
or, with ``coupled=False``, independently: then each foot's estimates are those of its navigator alone.
The feet start still, side by side and parallel (``FootSeparation.left_origin_m``/``right_origin_m``).
:func:`export_pair` is ``footnav export --left L --right R``: both feet's tracks written, as ``export``
writes one foot's.
"""

from __future__ import annotations

from pathlib import Path

from footnav.app.commands.export import (
    count_clipped_rates,
    foot_path,
    load_other_recording,
    recording_config,
    write_steps_csv,
    write_track,
)
from footnav.device.files.recordings import Recording
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.navigation.saturation import SaturatedRates, reconstruct_saturated_rates
from footnav.pipeline.two_feet import FootSeparation, FootSignals, TwoFeetResult, navigate_feet


def _signals(rec: Recording) -> tuple[FootSignals, SaturatedRates]:
    sat = reconstruct_saturated_rates(rec.t_s, rec.gyr_b_radps)
    return FootSignals(rec.t_start_s + rec.t_s, rec.acc_b_mps2, sat.gyr_b_radps, rec.rate_hz, sat.clipped_b), sat


def navigate_pair(
    left: Recording,
    right: Recording,
    *,
    coupled: bool = True,
    bound: FootSeparation | None = None,
    stance_levels: bool = True,
    profile: str | None = None,
) -> TwoFeetResult:
    """Navigate a left and a right recording together (module docstring).

    Parameters
    ----------
    left, right : Recording
        The feet's recordings (``footnav.app.read_recording``), stamped on one clock.
    coupled : bool
        Apply the inter-foot distance bound; False navigates the feet independently.
    bound : FootSeparation, optional
        The bound R (default ``DEFAULT_MAX_SEPARATION_M``), its noise, the feet's start positions and the
        relative heading constraint (default: on; ``heading=None`` the bound alone).
    stance_levels : bool
        Use the stance height levels (``footnav.pipeline.stance.levels``), as ``navigate`` does.
    profile : str, optional
        The unit noise profile of both (None: each recording's own).

    Returns
    -------
    TwoFeetResult
        Both feet's estimates from their first still period on (their ``t_s`` on the shared clock, s),
        and the times the bound acted.

    Raises
    ------
    FootnavError
        the recordings do not overlap in time, or a foot never stands still.
    """
    (sl, sat_l), (sr, sat_r) = _signals(left), _signals(right)
    overlap_s = min(sl.t_s[-1], sr.t_s[-1]) - max(sl.t_s[0], sr.t_s[0])
    if not overlap_s > 0.0:
        raise FootnavError(
            f"{left.name} ({sl.t_s[0]:.3f}-{sl.t_s[-1]:.3f} s) and {right.name} ({sr.t_s[0]:.3f}-{sr.t_s[-1]:.3f} s) "
            "do not overlap in time; two feet are navigated together on one clock (the files' time stamps)"
        )
    coupling = (bound or FootSeparation()) if coupled else None
    left_config = recording_config(left, profile, stance_levels=stance_levels)
    right_config = recording_config(right, profile, stance_levels=stance_levels)
    result = navigate_feet(sl, sr, left_config, coupling, right_config=right_config)
    for rec, nav, stats, sat in (
        (left, result.left, result.left_stats, sat_l),
        (right, result.right, result.right_stats, sat_r),
    ):
        if nav is None:
            raise FootnavError(f"{rec.name}: the unit is never still, so roll and pitch cannot be aligned")
        count_clipped_rates(stats, sat)
    return result


def export_pair(
    left: Path,
    right: Path,
    out: Path,
    *,
    coupling: str = "distance+heading",
    fmt: str | None = None,
    columns: str | None = None,
    profile: str | None = None,
    stance_levels: bool = True,
    steps_out: Path | None = None,
    gait_out: Path | None = None,
    out_format: str | None = None,
) -> str:
    """Navigate a left and a right recording together (:func:`navigate_pair`) and write each foot's track
    to ``<stem>-left<suffix>`` and ``<stem>-right<suffix>`` beside ``out`` (as ``export`` writes one, in
    ``out_format`` or as the suffix says), with ``steps_out`` and ``gait_out`` named alike; returns the summary.

    Parameters
    ----------
    left, right, out : Path
        The recordings, and the track's name.
    coupling : str
        ``"distance"``, ``"distance+heading"`` or ``"independent"``
        (``footnav.pipeline.two_feet.live.FEET_COUPLINGS``).
    fmt, columns, profile, stance_levels, steps_out, gait_out, out_format
        As for one recording (``footnav.app.commands.export.run_export``).

    Raises
    ------
    FootnavError
        a file cannot be read, the two do not overlap in time, or a foot never stands still.
    """
    from footnav.app.commands.export import track_format
    from footnav.pipeline.two_feet.live import coupling_bound

    track_format(out, out_format)  # a name that contradicts the format is refused before any work
    bound = coupling_bound(coupling)
    recs = [load_other_recording(p, fmt, columns) for p in (left, right)]
    result = navigate_pair(
        recs[0], recs[1], coupled=bound is not None, bound=bound, stance_levels=stance_levels, profile=profile
    )
    written, gait = [], []
    for foot, nav in (("left", result.left), ("right", result.right)):
        assert nav is not None  # navigate_pair raises otherwise
        write_track(nav, foot_path(out, foot), out_format)
        written.append(f"{len(nav)} rows to {foot_path(out, foot)}")
        if steps_out is not None:
            written.append(write_steps_csv(nav, foot_path(steps_out, foot)))
        if gait_out is not None:
            from footnav.app.api.gait_export import export_gait

            gait.append(export_gait(nav, foot_path(gait_out, foot), causal_from=0, label=f" {foot}"))
    how = f"coupled: {coupling_counts(result, bound)}" if bound is not None else "independent"
    return f"wrote {'; '.join(written)} (two feet, {how})" + "".join(f"\n{g}" for g in gait)


def coupling_counts(result: TwoFeetResult, bound: FootSeparation) -> str:
    """What the coupling did, as the live sessions' ``FeetLockstep.summary`` says it: the distance bound's
    corrections and, when ``bound`` has the relative heading, its updates."""
    heading = "" if bound.heading is None else f", {len(result.heading_updates)} relative heading updates"
    return f"{len(result.corrections)} corrections of the distance bound{heading}"
