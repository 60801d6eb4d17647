"""The foot filter's parameters, counters and carried state, as named types for the compiled kernels.

``FilterParams`` is a ``NamedTuple`` of floats: numba passes it to ``@njit`` code by value and reads
its fields by name (``par.sig_acc``). The filter's ``counters`` are an int64 array of counts only,
indexed by the ``CNT_*`` constants; what the filter carries between batches that is not a count
(the stance it is in, whether the last update was rejected) is a separate int64 array
``filter_state``, indexed by the ``STATE_*`` constants. Units are SI: m, s, rad; noise densities as
named by the fields of ``footnav.pipeline.navigation.profiles.UnitProfile``.
"""

from __future__ import annotations

from typing import NamedTuple


class FilterParams(NamedTuple):
    """Parameters of ``footnav.pipeline.navigation.eskf.run_filter`` (all floats)."""

    sig_acc: float
    """Specific-force noise per sample, m/s² (white noise at the rate and motion noise)."""
    sig_gyr: float
    """Angular-rate noise per sample, rad/s."""
    ba_rw: float
    """Accelerometer bias random walk, m/s³/√Hz."""
    bg_rw: float
    """Gyroscope bias random walk, rad/s²/√Hz."""
    zupt: float
    """Zero-velocity pseudo-measurement noise, m/s."""
    zaru: float
    """Zero-angular-rate pseudo-measurement noise, rad/s."""
    g: float
    """Local gravity, m/s²."""
    dt_max: float
    """Intervals this long or longer are gaps, s."""
    zaru_gate: float
    """χ² gate (3 degrees of freedom) of the zero-angular-rate update."""
    roll_lever: float
    """Distance from the IMU to the contact point a stance foot may roll about, m."""
    acc_scale: float
    """Specific-force noise as a fraction of the signal (scale, cross-axis errors)."""
    gyr_scale: float
    """Angular-rate noise as a fraction of the signal."""
    zupt_vert_stat: float
    """Vertical zero-velocity noise added at the detector's threshold (1σ at T/γ = 1), m/s."""
    zaru_gate_sig: float
    """Rate noise the zero-angular-rate gate tests against (the gyroscope's white noise), rad/s."""
    zupt_gate: float
    """Normalised innovation squared above which an unsure zero-velocity sample is skipped."""
    zupt_gate_ratio: float
    """T/γ above which the detector is unsure of a stance sample."""
    standing_turn: float
    """Vertical turn rate of a standing foot, added to the zero-rate noise, rad/s (0: none)."""
    standing_after: float
    """Stance samples in a row after which a foot is standing."""


# counters of run_filter: counts only
CNT_BAD_DT, CNT_GAP, CNT_BAD_SAMPLE, CNT_UPDATES, CNT_ZARU, CNT_ZARU_REJECTED, CNT_ZUPT_REJECTED = range(7)
N_CNT = 7

# the filter's state carried between batches besides x and P
STATE_LAST_REJECTED = 0  # 1 when the last sample's zero-velocity update was rejected
STATE_STANCE_RUN = 1  # stance samples in a row up to the current one
STATE_STARTED = 2  # 1 once the first stance (the still start) has ended
N_FILTER_STATE = 3
