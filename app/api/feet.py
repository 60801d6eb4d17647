"""A left and a right recording navigated as one problem: :func:`navigate_pair`.

The two recordings are put on one clock by their time stamps (each file's own clock,
``Recording.t_start_s`` plus its sample times; both files must come from one clock, e.g. one logger or
synchronised units), their saturated gyroscope stretches are reconstructed as for one foot
(``footnav.pipeline.navigation.saturation``), and ``footnav.pipeline.two_feet.navigate_feet`` runs their
navigators in lockstep, coupled by the inter-foot distance bound (``footnav.pipeline.two_feet.separation``)
or, with ``coupled=False``, independently: then each foot's estimates are those of its navigator alone.
The feet start still, side by side and parallel (``FootSeparation.left_origin_m``/``right_origin_m``).
"""

from __future__ import annotations

from footnav.app.commands.export import recording_config
from footnav.device.files.recordings import Recording
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.navigation.saturation import reconstruct_saturated_rates
from footnav.pipeline.two_feet import FootSeparation, FootSignals, TwoFeetResult, navigate_feet


def _signals(rec: Recording) -> FootSignals:
    sat = reconstruct_saturated_rates(rec.t_s, rec.gyr_b_radps)
    return FootSignals(rec.t_start_s + rec.t_s, rec.acc_b_mps2, sat.gyr_b_radps, rec.rate_hz, sat.clipped_b)


def navigate_pair(
    left: Recording,
    right: Recording,
    *,
    coupled: bool = True,
    bound: FootSeparation | None = None,
    stance_levels: bool = True,
) -> TwoFeetResult:
    """Navigate a left and a right recording together (module docstring).

    Parameters
    ----------
    left, right : Recording
        The feet's recordings (``footnav.app.read_recording``), stamped on one clock.
    coupled : bool
        Apply the inter-foot distance bound; False navigates the feet independently.
    bound : FootSeparation, optional
        The bound R (default ``DEFAULT_MAX_SEPARATION_M``), its noise and the feet's start positions.
    stance_levels : bool
        Use the stance height levels (``footnav.pipeline.stance.levels``), as ``navigate`` does.

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
    sl, sr = _signals(left), _signals(right)
    overlap_s = min(sl.t_s[-1], sr.t_s[-1]) - max(sl.t_s[0], sr.t_s[0])
    if not overlap_s > 0.0:
        raise FootnavError(
            f"{left.name} ({sl.t_s[0]:.3f}-{sl.t_s[-1]:.3f} s) and {right.name} ({sr.t_s[0]:.3f}-{sr.t_s[-1]:.3f} s) "
            "do not overlap in time; two feet are navigated together on one clock (the files' time stamps)"
        )
    coupling = (bound or FootSeparation()) if coupled else None
    left_config = recording_config(left, stance_levels=stance_levels)
    right_config = recording_config(right, stance_levels=stance_levels)
    result = navigate_feet(sl, sr, left_config, coupling, right_config=right_config)
    for rec, nav in ((left, result.left), (right, result.right)):
        if nav is None:
            raise FootnavError(f"{rec.name}: the unit is never still, so roll and pitch cannot be aligned")
    return result
