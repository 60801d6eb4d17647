"""The schema of a capture's header: what each unit's recorded settings, its foot name and the session
record may hold.

A capture is a file from anywhere, so its header is input to check, not to trust: the replay takes
its settings (output mode, rate, navigator settings, lever arm, IMU mask) into the same code a live
session runs, and a foot name becomes part of the name of the files ``footnav export`` writes.
:func:`checked_unit_fields` and :func:`check_session` (called as ``footnav.device.files.capture.iter_capture``
reads the header) raise an :class:`~footnav.pipeline.errors.InputFormatError` naming the first value
that does not fit, e.g. ``capture metadata: unit 'foot': rate_hz is 'abc', expected a positive number``.

Types, ranges and names are checked; keys this version does not know are left alone (a newer
footnav may record more), as are missing keys (older captures record fewer; the replay has defaults).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Final

from footnav.pipeline.errors import InputFormatError

MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
"""The first and last bytes of every MCAP file (footnav's captures are MCAP files)."""
FOOT_NAME: Final = re.compile(r"[A-Za-z0-9_-]{1,32}")
"""A foot (unit) name: letters, digits, ``_`` and ``-`` (``foot``, ``left``, ``right``); never a path."""
MODES: Final = ("normal_imu", "dual_imu_raw", "raw_imu_fused", "calibration_raw_imu", "ins", "steps")
"""``settings.mode``: the output a unit was started in."""
STANCE_MODES: Final = ("inertial", "height", "and", "or")
"""``settings.stance``: the ToF units' stance detector mode (``footnav.pipeline.stance.height_detector``)."""
MAX_RATE_DIVIDER_LOG2: Final = 14
MAX_RATE_HZ: Final = 100_000.0
"""The highest output rate a capture may claim, Hz (the units run at 1 kHz and below)."""
MAX_IMU_MASK: Final = 0x0F
"""The raw output's IMU mask: the four IMUs of the largest supported board."""
NAV_TABLES: Final = ("profile", "detector", "filter", "tof")
"""The tables of ``settings.nav_config`` (``footnav.app.config.Config.to_json``)."""
_VECTORS: Final = ("lever_b_m", "dir_b")
"""``nav_config.tof`` keys that hold one [x, y, z] per sensor."""


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _is_int(v: Any, lo: int, hi: int) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi


def _is_vector(v: Any) -> bool:
    return isinstance(v, list) and len(v) == 3 and all(_is_number(c) for c in v)


def _unit_models() -> tuple[str, ...]:
    from footnav.device.models import UNIT_MODELS

    return tuple(UNIT_MODELS)


SETTINGS: Final[Mapping[str, tuple[Callable[[Any], bool], Callable[[], str]]]] = {
    "mode": (lambda v: v in MODES, lambda: "one of " + ", ".join(MODES)),
    "model": (lambda v: v in _unit_models(), lambda: "one of " + ", ".join(_unit_models())),
    "rate_divider_log2": (
        lambda v: _is_int(v, 0, MAX_RATE_DIVIDER_LOG2),
        lambda: f"a whole number from 0 to {MAX_RATE_DIVIDER_LOG2}",
    ),
    "rate_hz": (
        lambda v: _is_number(v) and 0 < v <= MAX_RATE_HZ,
        lambda: f"a positive number (Hz) up to {MAX_RATE_HZ:g}",
    ),
    "nav_config": (lambda v: isinstance(v, dict), lambda: "an object of navigator settings"),
    "extensions": (lambda v: isinstance(v, bool), lambda: "true or false"),
    "stance": (lambda v: v in STANCE_MODES, lambda: "one of " + ", ".join(STANCE_MODES)),
    "dual_imu_lever_b_m": (_is_vector, lambda: "a list of 3 finite numbers (m)"),
    "fused_imu_mask": (lambda v: _is_int(v, 1, MAX_IMU_MASK), lambda: f"a whole number from 1 to {MAX_IMU_MASK}"),
    "imu_mask": (lambda v: _is_int(v, 1, MAX_IMU_MASK), lambda: f"a whole number from 1 to {MAX_IMU_MASK}"),
    "ins_state_ids": (
        lambda v: isinstance(v, list) and 0 < len(v) <= 32 and all(_is_int(i, 0, 255) for i in v),
        lambda: "a list of 1 to 32 state ids (whole numbers from 0 to 255)",
    ),
}
"""Each known ``settings`` key: the test its value must pass, and what was expected (for the message)."""


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


_S: Final = (0.0, 600.0, False)  # a time span, s: (lo, hi, lo allowed)
_THRESHOLD: Final = (1e-9, 1e12, True)
_SIGMA: Final = (1e-9, 1e3, True)  # squared and divided by
NAV_RANGES: Final[Mapping[str, tuple[float, float, bool]]] = {
    "detector.window_s": (0.0, 10.0, False),
    "detector.sigma_acc_mps2": _SIGMA,
    "detector.sigma_gyr_radps": _SIGMA,
    "detector.gravity_mps2": (0.0, 100.0, False),
    "detector.threshold": _THRESHOLD,
    "detector.history_s": _S,
    "detector.update_s": _S,
    "detector.margin_decades": (0.0, 20.0, True),
    "detector.motion_decades": (0.0, 20.0, True),
    "detector.min_threshold": _THRESHOLD,
    "detector.max_threshold": _THRESHOLD,
    "detector.min_stance_s": (0.0, 60.0, True),
    "detector.stance_hysteresis_decades": (0.0, 20.0, True),
    "filter.align_s": _S,
    "filter.align_max_rate_radps": _SIGMA,
    "filter.align_max_acc_dev_mps2": _SIGMA,
    "filter.dt_max_s": (0.0, 60.0, False),
    "filter.max_wait_s": (0.0, 1e6, False),
    "filter.gravity_mps2": (0.0, 100.0, True),  # 0: recorded before gravity was configured (|f| at rest)
    "tof.sigma_range_m": _SIGMA,
    "tof.sigma_floor_m": _SIGMA,
}
"""``nav_config.<table>.<key>``: the range a number must be in (the filter's arrays are sized by the
time spans, and its arithmetic divides by the sigmas); other numbers of the tables are in
:data:`DEFAULT_RANGE` (densities, sigmas and factors of ``profile``, the initial sigmas of ``filter``)."""
DEFAULT_RANGE: Final = (0.0, 1e6, True)
NAV_NAMES: Final[Mapping[str, tuple[str, ...]]] = {"detector.kind": ("shoe", "amv", "amag", "are")}
"""``nav_config`` keys that hold one of a few names (``footnav.pipeline.stance.detectors.DETECTOR_KINDS``)."""
NAV_FLAGS: Final = ("detector.adaptive", "filter.stance_levels", "filter.step_smoothing")


def nav_value_problem(table: str, key: str, value: Any) -> str | None:
    """What is wrong with ``nav_config.<table>.<key>`` (what was expected), or None."""
    name = f"{table}.{key}"
    if table == "tof" and key in _VECTORS:
        ok = isinstance(value, list) and 0 < len(value) <= 16 and all(_is_vector(v) for v in value)
        return None if ok else "a list of [x, y, z] vectors (one per sensor)"
    if name in NAV_NAMES:
        return None if value in NAV_NAMES[name] else "one of " + ", ".join(NAV_NAMES[name])
    if name in NAV_FLAGS:
        return None if isinstance(value, bool) else "true or false"
    if name == "profile.name":
        return None if isinstance(value, str) and 0 < len(value) <= 64 and value.isprintable() else "a name"
    lo, hi, lo_allowed = NAV_RANGES.get(name, DEFAULT_RANGE)
    in_range = _is_number(value) and (lo <= value if lo_allowed else lo < value) and value <= hi
    if in_range:
        return None
    return f"a number from {lo:g} to {hi:g}" if lo_allowed else f"a number over {lo:g}, up to {hi:g}"


def _check_nav_config(nav: dict[str, Any], fail: Callable[[str, Any, str], InputFormatError]) -> None:
    for table in NAV_TABLES:
        if table not in nav:
            continue
        values = nav[table]
        if not isinstance(values, dict):
            raise fail(f"nav_config.{table}", values, "an object")
        for key, value in values.items():
            problem = nav_value_problem(table, key, value)
            if problem is not None:
                raise fail(f"nav_config.{table}.{key}", value, problem)


def checked_unit_fields(path: Path, md: Mapping[str, str]) -> dict[str, Any]:
    """The foot name and the settings of one ``footnav.unit`` record, checked against the schema.

    Returns
    -------
    dict
        ``{"foot": name, "settings": the decoded settings}``.

    Raises
    ------
    InputFormatError
        the foot name or a setting does not fit (the message names it, its value and what was expected).
    """
    foot = md.get("foot", "foot")
    if not FOOT_NAME.fullmatch(foot):
        raise InputFormatError(
            f"{path}: capture metadata: foot is {_shown(foot)}, expected a name of letters, digits, _ and - "
            "(foot, left, right)"
        )

    def fail(name: str, value: Any, expected: str) -> InputFormatError:
        return InputFormatError(
            f"{path}: capture metadata: unit {foot!r}: {name} is {_shown(value)}, expected {expected}"
        )

    try:
        settings = json.loads(md.get("settings", "{}"))
    except (json.JSONDecodeError, RecursionError):
        raise fail("settings", md.get("settings"), "a JSON object") from None
    if not isinstance(settings, dict):
        raise fail("settings", settings, "a JSON object")
    for key, (ok, expected) in SETTINGS.items():
        if key in settings and not ok(settings[key]):
            raise fail(key, settings[key], expected())
    if isinstance(settings.get("nav_config"), dict):
        _check_nav_config(settings["nav_config"], fail)
    return {"foot": foot, "settings": settings}


def check_session(path: Path, session: Mapping[str, str], format_version: int) -> None:
    """The ``footnav.session`` record's values that the reader uses (``format_version``: the newest
    capture format this footnav reads).

    Raises
    ------
    InputFormatError
        ``monotonic_to_unix_ns`` is not a whole number, or ``format_version`` is not one this footnav
        reads.
    """
    offset = session.get("monotonic_to_unix_ns", "0")
    if not re.fullmatch(r"-?[0-9]{1,20}", offset):
        raise InputFormatError(
            f"{path}: capture metadata: monotonic_to_unix_ns is {_shown(offset)}, expected a whole number (ns)"
        )
    version = session.get("format_version", str(format_version))
    if not re.fullmatch(r"[0-9]{1,6}", version) or not 1 <= int(version) <= format_version:
        raise InputFormatError(
            f"{path}: capture metadata: format_version is {_shown(version)}, expected 1 to {format_version} "
            "(a capture from a newer footnav needs that version to read it)"
        )


def starts_like_capture(path: Path) -> bool | None:
    """Whether the file starts with :data:`MCAP_MAGIC` (``footnav.device.files.capture`` checks the rest); None
    when it cannot be read."""
    try:
        with path.open("rb") as f:
            return f.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return None
