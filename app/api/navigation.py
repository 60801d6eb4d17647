"""The Python API: navigate arrays or a recording, read recordings, gait parameters per stride.

The same code as the command line, not a second implementation: :func:`read_recording` is the loading of
``footnav export`` (``footnav.app.commands.export.load_other_recording``, so every format and ``--columns``
mapping it reads; a footnav capture's IMU samples, decoded as replay decodes them:
``footnav.app.commands.smooth_capture.captured_samples``), and :func:`navigate` runs
``footnav.app.commands.export.navigate_recording`` (saturated
gyroscope stretches reconstructed, the samples before the first still period navigated backwards from it,
the RTS or step smoother when asked); :func:`gait_parameters` is ``footnav.pipeline.gait.parameters``. SI
units and the navigation frame of the whole project: right-handed, z up, origin at the start position
(docs/design/architecture.md). ``to_pandas`` needs the optional extra ``footnav[pandas]``. The user guide,
with a worked example that the test suite runs: docs/guide/python-api.md.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Literal, overload

import numpy as np
from footnav.app.commands.export import (
    EXPORT_COLUMNS,
    load_other_recording,
    navigate_recording,
    write_track_parquet,
)
from footnav.device.files.capture_schema import starts_like_capture
from footnav.device.files.recordings import Recording, _nominal_rate
from footnav.pipeline.errors import FootnavError, MissingExtraError
from footnav.pipeline.gait import parameters
from footnav.pipeline.gait.parameters import StrideParameters
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavStats
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import pandas

F64 = NDArray[np.float64]
Smoothing = Literal["whole", "step"]


@dataclass(frozen=True)
class Navigation:
    """One foot's navigation solution, one estimate per sample (:func:`navigate`).

    Attributes
    ----------
    nav
        the estimates as the pipeline gives them (``footnav.pipeline.nav_types.NavBatch``); the
        properties below are its arrays.
    stats
        what the navigator counted: updates, samples skipped or navigated backwards, clipped rates
        (``footnav.pipeline.navigation.navigator.NavStats``).
    profile
        the unit profile navigated with (``footnav.pipeline.navigation.profiles``).
    smooth
        ``"whole"`` (RTS smoother), ``"step"`` (step smoother) or None (the causal filter).
    name
        the recording's name (file stem), or ``"arrays"``.
    """

    nav: NavBatch
    stats: NavStats
    profile: str
    smooth: Smoothing | None
    name: str

    def __len__(self) -> int:
        return len(self.nav)

    @property
    def t_s(self) -> F64:
        """(n,) sample times, s."""
        return self.nav.t_s

    @property
    def pos_n_m(self) -> F64:
        """(n, 3) position of the IMU, navigation frame (x, y horizontal, z up), m."""
        return self.nav.pos_n_m

    @property
    def vel_n_mps(self) -> F64:
        """(n, 3) velocity, navigation frame, m/s."""
        return self.nav.vel_n_mps

    @property
    def quat_nb_wxyz(self) -> F64:
        """(n, 4) attitude, body to navigation, unit quaternion, scalar first."""
        return self.nav.quat_nb_wxyz

    @property
    def stance(self) -> NDArray[np.bool_]:
        """(n,) True where the zero-velocity detector declared the foot still."""
        return self.nav.stance

    @property
    def pos_cov_n_m2(self) -> F64:
        """(n, 3, 3) position covariance, m² (the smoothers': of the smoothed position)."""
        return self.nav.pos_cov_n_m2

    @property
    def clearance_m(self) -> F64:
        """(n,) height of the IMU above the floor of its stance (in swing: of the stance it left), m."""
        return self.nav.clearance_m

    def to_pandas(self) -> pandas.DataFrame:
        """The estimates as a table: the columns of ``footnav export`` (``t``; ``x y z``, m; ``vx vy
        vz``, m/s; ``qw qx qy qz``; ``stance``; ``var_x var_y var_z``, m²), one row per sample.

        Raises
        ------
        ImportError
            pandas is not installed (``pip install 'footnav[pandas]'``).
        """
        pd = _pandas()
        var = np.diagonal(self.nav.pos_cov_n_m2, axis1=1, axis2=2)
        values = np.column_stack([self.t_s, self.pos_n_m, self.vel_n_mps, self.quat_nb_wxyz, self.stance, var])
        frame = pd.DataFrame(values, columns=list(EXPORT_COLUMNS))
        frame["stance"] = self.stance
        return frame

    def to_parquet(self, path: str | os.PathLike[str]) -> None:
        """Write the estimates to a Parquet file, the columns and values of ``footnav export -o TRACK.parquet``
        (``footnav.app.commands.export.write_track_parquet``: ``to_pandas``'s, with every bit of each value and
        each column's unit in the schema).

        Raises
        ------
        ImportError
            pyarrow is not installed (``pip install 'footnav[parquet]'``).
        FootnavError
            the file cannot be written.
        """
        write_track_parquet(self.nav, Path(path))


@overload
def navigate(
    acc_mps2: Recording, gyr_rads: None = None, t_s: None = None, *, profile: str | None = None,
    smooth: bool | Smoothing = False, stance_levels: bool = True,
) -> Navigation: ...  # fmt: skip
@overload
def navigate(
    acc_mps2: ArrayLike, gyr_rads: ArrayLike, t_s: ArrayLike, *, profile: str | None = None,
    smooth: bool | Smoothing = False, stance_levels: bool = True,
) -> Navigation: ...  # fmt: skip
def navigate(
    acc_mps2: ArrayLike | Recording,
    gyr_rads: ArrayLike | None = None,
    t_s: ArrayLike | None = None,
    *,
    profile: str | None = None,
    smooth: bool | Smoothing = False,
    stance_levels: bool = True,
) -> Navigation:
    """Navigate one foot-mounted IMU's samples, as ``footnav export`` does.

    Parameters
    ----------
    acc_mps2
        (n, 3) specific force in the sensor's axes, m/s²; or a :class:`Recording` (from
        :func:`read_recording`), whose samples and profile are used, and then ``gyr_rads`` and ``t_s``
        are left out.
    gyr_rads
        (n, 3) angular rate in the same axes, rad/s.
    t_s
        (n,) sample times, increasing, s (any start).
    profile
        the unit profile (``footnav.pipeline.navigation.profiles.PROFILES``: ``mpu6500x4``,
        ``adis16367``, ``gx3``, ``generic``); None: the recording's, or ``generic`` for arrays.
    smooth
        False: the causal filter, as live; True or ``"whole"``: the RTS smoother of the whole recording;
        ``"step"``: each step smoothed once it ends, as a live session with step smoothing shows it.
    stance_levels
        hold the foot at the height of the floor it stands on (``footnav.pipeline.stance.levels``).

    Returns
    -------
    Navigation
        one estimate per sample.

    Raises
    ------
    FootnavError
        the samples never stand still for half a second (the alignment needs it), the profile is
        unknown, or the arrays are not (n, 3), (n, 3) and (n,) with increasing times
        (``footnav.pipeline.errors.InputFormatError``).

    Examples
    --------
    >>> import numpy as np
    >>> from footnav.app import navigate
    >>> t = np.arange(2000) / 200.0  # ten seconds standing still at 200 Hz
    >>> acc = np.tile([0.0, 0.0, 9.80665], (t.size, 1))
    >>> result = navigate(acc, np.zeros((t.size, 3)), t)
    >>> result.pos_n_m.shape
    (2000, 3)
    >>> bool(np.abs(result.pos_n_m).max() < 0.01)  # still: it stays where it started
    True
    """
    if isinstance(acc_mps2, Recording):
        if gyr_rads is not None or t_s is not None:
            raise TypeError("navigate(recording) takes the samples from the recording: leave out gyr_rads and t_s")
        rec = acc_mps2
    else:
        if gyr_rads is None or t_s is None:
            raise TypeError("navigate(acc_mps2, gyr_rads, t_s) needs all three arrays (or one Recording)")
        rec = _recording_of(acc_mps2, gyr_rads, t_s, profile or "generic")
    how: Smoothing | None = "whole" if smooth is True else (smooth or None)
    nav, stats = navigate_recording(rec, profile, how, stance_levels)
    return Navigation(nav, stats, profile or rec.profile, how, rec.name)


def _recording_of(acc: ArrayLike, gyr: ArrayLike, t: ArrayLike, profile: str) -> Recording:
    """Arrays as a recording, checked as the loaders check a file's."""
    acc_b, gyr_b, t_s = (np.array(x, dtype=np.float64) for x in (acc, gyr, t))
    n = t_s.shape[0] if t_s.ndim == 1 else -1
    if n < 2 or acc_b.shape != (n, 3) or gyr_b.shape != (n, 3):
        raise FootnavError(
            f"expected acc_mps2 (n, 3), gyr_rads (n, 3) and t_s (n,) with n >= 2; got {acc_b.shape}, "
            f"{gyr_b.shape} and {t_s.shape}"
        )
    return Recording("arrays", "arrays", t_s, acc_b, gyr_b, _nominal_rate(t_s), profile)


def read_recording(
    path: str | os.PathLike[str], *, format: str | None = None, columns: str | None = None, foot: str | None = None
) -> Recording:
    """Load a recording, as ``footnav export`` and ``footnav replay`` read it.

    Parameters
    ----------
    path
        the file: a PyShoe VICON trial (``.mat``), an x-io CSV, an OpenShoe ``data_inert.txt``, a raw
        log of an OpenShoe/MIMU unit's stream, any CSV with ``columns``
        (``footnav.device.files.recordings``; docs/guide/recordings.md), or a footnav capture
        (``.mcap``): the IMU samples of one foot, decoded as ``footnav replay`` decodes them.
    format
        the loader (``pyshoe``, ``xio``, ``openshoe``, ``csv``, ``mimu-log``); None: recognised from the
        file's content.
    columns
        a generic CSV's columns and units, as the commands' ``--columns`` takes them, e.g.
        ``"time=t:s,acc=ax;ay;az:m/s2,gyr=gx;gy;gz:rad/s"``.
    foot
        of a capture of two feet, which one (``left``, ``right``); None: the only one.

    Returns
    -------
    Recording
        the samples in SI units (``t_s``, ``acc_b_mps2``, ``gyr_b_radps``, ``rate_hz``), the unit
        profile that fits the sensor, and the ground truth where the file has it (``gt_pos_m``). A
        capture's profile is its unit's; :func:`navigate` navigates its samples as a recording's, with
        the default settings (``footnav export`` replays a capture with the settings it was recorded
        with, and with its ToF readings, which a ``Recording`` does not hold).

    Raises
    ------
    FootnavError
        the file cannot be read, or is not a recording footnav reads
        (``footnav.pipeline.errors.InputFormatError``, a subclass); a capture holds no IMU samples of
        that foot (a unit's own solution, a dual-IMU board's two IMUs).
    """
    file = Path(path)
    if starts_like_capture(file):
        if format is not None or columns is not None:
            raise FootnavError(f"{file} is a footnav capture: format and columns are for recordings of other tools")
        return _capture_recording(file, foot)
    if foot is not None:
        raise FootnavError(f"{file}: foot picks a foot of a footnav capture; this is a recording of another tool")
    return load_other_recording(file, format, columns)


def _capture_recording(path: Path, foot: str | None) -> Recording:
    """One foot's IMU samples of a footnav capture (:func:`read_recording`)."""
    from footnav.app.commands.replay import ReplayOptions, checked_summary, onboard_outputs
    from footnav.app.commands.smooth_capture import captured_samples
    from footnav.app.config import apply_capture_settings, defaults

    cfg = defaults()
    summary = checked_summary(ReplayOptions(path=path, config=cfg, viewer=False))
    feet = summary.info.feet
    if foot is None and len(feet) != 1:
        raise FootnavError(f"{path} holds the feet {', '.join(feet)}: read_recording(..., foot=...) picks one")
    chosen = foot if foot is not None else feet[0]
    if chosen not in feet:
        raise FootnavError(f"{path} holds no foot {chosen!r}; it holds {', '.join(feet)}")
    unit = next(u for u in summary.info.units if u.foot == chosen)
    if onboard_outputs(summary).get(chosen) or "dual_imu_lever_b_m" in unit.settings:
        raise FootnavError(
            f"{path}: the {chosen} unit sent its own solution or a dual-IMU board's two IMUs, not one IMU's samples "
            "(footnav export and replay show what it sent)"
        )
    recorded = unit.settings.get("nav_config")
    if isinstance(recorded, dict):
        apply_capture_settings(cfg, recorded, f"capture {path.name}")
    collector = captured_samples(path, summary, cfg)[chosen]
    if not collector.batches:
        raise FootnavError(f"{path}: the {chosen} unit sent no IMU samples")
    notes = ["ToF readings left out (footnav export navigates them)"] if unit.settings.get("extensions") else []
    return Recording(
        name=path.stem if len(feet) == 1 else f"{path.stem}-{chosen}",
        format="capture",
        t_s=np.concatenate([b.t_s for b in collector.batches]),
        acc_b_mps2=np.concatenate([b.acc_b_mps2 for b in collector.batches]),
        gyr_b_radps=np.concatenate([b.gyr_b_radps for b in collector.batches]),
        rate_hz=collector.rate_hz,
        profile=str(cfg["unit.profile"]),
        notes=notes,
    )


def gait_parameters(result: Navigation | NavBatch) -> StrideParameters:
    """The gait parameters of each stride of a navigated foot (``footnav.pipeline.gait.parameters``).

    Parameters
    ----------
    result
        :func:`navigate`'s result (or a ``NavBatch`` of the causal filter).

    Returns
    -------
    StrideParameters
        one entry per stride (length, duration, cadence, speed, stance and swing time and share,
        turning angle and its 1σ, lateral deviation, maximum and mid-swing minimum clearance), with
        ``columns()`` for a table and ``footnav.pipeline.gait.parameters.summarize`` for the mean, SD
        and CV over the recording.
    """
    if isinstance(result, NavBatch):
        return parameters.gait_parameters(result)
    causal_from = None if result.smooth else result.stats.samples_navigated_backwards
    return parameters.gait_parameters(result.nav, causal_from=causal_from)


def _pandas() -> ModuleType:
    """The pandas module, or a :class:`MissingExtraError` (an ImportError) that names the extra."""
    try:
        import pandas
    except ImportError:
        raise MissingExtraError(
            "to_pandas() needs pandas, an optional extra of footnav: pip install 'footnav[pandas]'"
        ) from None
    return pandas
