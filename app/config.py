"""Configuration: defaults < ``footnav.toml`` (or ``--config FILE``) < the command line, and where
each value came from.

The file (TOML, read with :mod:`tomllib`)::

    [session]
    sessions_dir = "sessions"   # capture files go here
    capture = true              # capture every live session (and the demo)
    capture_flush_s = 1.0       # captured bytes reach the OS at most this late (what a crash can lose)
    [unit]
    profile = "mpu6500x4"       # a built-in profile or one of [profiles.NAME]
    rate_divider = 0            # output every 2**K samples of the unit's base rate (K = 0..14)
    [filter]                    # footnav.pipeline.navigation.navigator.NavConfig (SI units, radians)
    align_s = 0.5
    [detector]                  # the dataclass of NavConfig.detector (footnav.pipeline.stance.detectors)
    threshold = 25.0
    [tof]                       # the ToF sensors: TofConfig fields lever_b_m, dir_b, sigma_range_m, sigma_floor_m
    sigma_range_m = 0.01
    [calibration]
    dir = ""                    # calibration files (default: $FOOTNAV_CALIBRATION_DIR, else
                                # $XDG_CONFIG_HOME/footnav/calibration, else ~/.config/footnav/calibration)
    apply = true                # apply a unit's calibration file when it connects or its capture replays
    [profiles.myshoe]           # a unit profile: a built-in base plus UnitProfile fields
    base = "mpu6500x4"          # (footnav.pipeline.navigation.profiles)
    gyr_bias_init_radps = 0.003

Keys map one to one onto the dataclass fields named above, with the same meaning and units; an unknown key or a
wrong type is an error naming the file, the key and what is allowed. ``[tof]`` holds the unit's hardware only
(where each range sensor sits and looks, in body axes, and its noise), not ``TofConfig``'s floor-reference and
gating constants. A capture records the [tof] values in force, and its replay uses them.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

from footnav.device.files.capture import FLUSH_PERIOD_S
from footnav.device.files.capture_schema import NAV_TABLES, nav_value_problem
from footnav.pipeline.aiding.tof_types import TofConfig
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.navigation.navigator import NavConfig
from footnav.pipeline.navigation.profiles import PROFILES, UnitProfile
from footnav.pipeline.stance.height_detector import HEIGHT_MODES, HeightDetectorParams, HeightMode

DEFAULT_FILE = "footnav.toml"
DEFAULT_SESSIONS_DIR = "sessions"

DEFAULT = "default"
CLI = "command line"

_SESSION_DEFAULTS: dict[str, Any] = {
    "sessions_dir": DEFAULT_SESSIONS_DIR,
    "capture": True,
    "capture_flush_s": FLUSH_PERIOD_S,
}
_UNIT_DEFAULTS: dict[str, Any] = {"profile": "mpu6500x4", "rate_divider": 0}
_CALIBRATION_DEFAULTS: dict[str, Any] = {"dir": "", "apply": True}
_FILTER_FIELDS = {f.name: f for f in dataclasses.fields(NavConfig) if f.name not in ("profile", "detector")}
_DETECTOR_CLS = type(NavConfig().detector)
"""The detector settings dataclass of ``NavConfig.detector`` (footnav.pipeline.stance.detectors)."""
_DETECTOR_FIELDS = {f.name: f for f in dataclasses.fields(_DETECTOR_CLS)}
_PROFILE_FIELDS = {f.name: f for f in dataclasses.fields(UnitProfile) if f.name != "name"}
_TOF_KEYS = ("lever_b_m", "dir_b", "sigma_range_m", "sigma_floor_m")
"""The ``TofConfig`` fields of the [tof] section (module docstring)."""
_SECTIONS = ("session", "unit", "calibration", "filter", "detector", "tof")


class ConfigError(FootnavError):
    """The configuration file or a setting is invalid."""


@dataclass(frozen=True, slots=True)
class Setting:
    """A value and where it came from (``default``, ``file PATH``, ``command line``, ``capture FILE``)."""

    value: Any
    source: str


@dataclass
class Config:
    """The effective configuration.

    Attributes
    ----------
    values
        ``section.key`` -> :class:`Setting` for session, unit, filter and detector keys.
    profiles
        Every known unit profile (built-in and from the file), with its source.
    file
        The configuration file read, if any.
    """

    values: dict[str, Setting]
    profiles: dict[str, tuple[UnitProfile, str]] = field(default_factory=dict)
    file: Path | None = None

    def __getitem__(self, key: str) -> Any:
        return self.values[key].value

    def source(self, key: str) -> str:
        return self.values[key].source

    def profile(self) -> UnitProfile:
        name = self["unit.profile"]
        try:
            return self.profiles[name][0]
        except KeyError:
            known = ", ".join(sorted(self.profiles))
            raise ConfigError(
                f"unknown unit profile {name!r} ({self.source('unit.profile')}); known: {known}"
            ) from None

    def detector(self) -> Any:
        """The zero-velocity detector settings (``NavConfig.detector``'s dataclass)."""
        return _DETECTOR_CLS(**{k: self[f"detector.{k}"] for k in _DETECTOR_FIELDS})

    def nav_config(self) -> NavConfig:
        """The navigator settings (``footnav.pipeline.navigation.navigator.NavConfig``) this configuration describes."""
        return NavConfig(
            profile=self.profile(),
            detector=self.detector(),
            **{k: self[f"filter.{k}"] for k in _FILTER_FIELDS},
        )

    def tof_config(self, stance: str = "inertial") -> TofConfig:
        """The ToF aiding settings: the [tof] section, with the stance detector mode ``stance``
        (inertial, height, and, or; ``footnav.pipeline.stance.height_detector``)."""
        if stance not in HEIGHT_MODES:
            raise ConfigError(f"unknown stance detector {stance!r}; expected one of {', '.join(HEIGHT_MODES)}")
        levers, dirs = self["tof.lever_b_m"], self["tof.dir_b"]
        if len(levers) != len(dirs):
            raise ConfigError(
                f"[tof] has {len(levers)} lever arms ({self.source('tof.lever_b_m')}) but {len(dirs)} viewing "
                f"directions ({self.source('tof.dir_b')}): one of each per sensor"
            )
        if any(math.hypot(*d) == 0.0 for d in dirs):
            raise ConfigError(f"[tof] dir_b ({self.source('tof.dir_b')}): a viewing direction is zero")
        return TofConfig(
            **{k: self[f"tof.{k}"] for k in _TOF_KEYS}, detector=HeightDetectorParams(mode=cast(HeightMode, stance))
        )

    def set(self, key: str, value: Any, source: str) -> None:
        """Override one value (``None`` leaves it alone)."""
        if value is None:
            return
        if key not in self.values:
            raise ConfigError(f"unknown setting {key!r}")
        self.values[key] = Setting(_coerce(key, value, self.values[key].value, source), source)

    def lines(self) -> list[str]:
        """``key = value  # source`` lines, as ``footnav config`` prints them (TOML-like)."""
        out: list[str] = []
        width = max(len(k) for k in self.values) + 2
        section = ""
        for key, s in self.values.items():
            sec, _, name = key.partition(".")
            if sec != section:
                out.append(f"{'' if not out else chr(10)}[{sec}]")
                section = sec
            out.append(f"{name + ' = ' + toml_value(s.value):<{width + 24}}  # {s.source}")
        prof, src = self.profiles.get(self["unit.profile"], (None, ""))
        if prof is not None:
            out.append(f"\n# unit profile {prof.name!r} in use ({src})")
            out.append(f"[profiles.{prof.name}]")
            for name in _PROFILE_FIELDS:
                out.append(f"{name} = {toml_value(getattr(prof, name))}")
        return out

    def to_json(self) -> dict[str, Any]:
        """The navigator settings as plain JSON values (for a capture header)."""
        nav = self.nav_config()
        return {
            "profile": dataclasses.asdict(nav.profile),
            "detector": dataclasses.asdict(nav.detector),
            "filter": {k: getattr(nav, k) for k in _FILTER_FIELDS},
            "tof": {k: _json(self[f"tof.{k}"]) for k in _TOF_KEYS},
        }


def _json(value: Any) -> Any:
    """Tuples (the sensors' vectors) as JSON lists."""
    return [_json(v) for v in value] if isinstance(value, tuple) else value


def toml_value(value: Any) -> str:
    """``value`` as TOML writes it (``true``, ``"text"``, ``[x, y, z]``)."""
    if isinstance(value, tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value)


def _coerce(key: str, value: Any, default: Any, source: str) -> Any:
    """Check ``value`` against the type of the default; ints are fine where floats are expected; a
    tuple of 3-vectors (the ToF sensors' lever arms or directions) is a non-empty list of [x, y, z];
    the navigator's numbers must be finite and in range (the ranges a capture's header is checked
    against, ``footnav.device.files.capture_schema.NAV_RANGES``)."""
    if isinstance(default, tuple):
        vectors = value if isinstance(value, list | tuple) else None
        if not vectors or not all(
            isinstance(v, list | tuple)
            and len(v) == 3
            and all(isinstance(c, int | float) and not isinstance(c, bool) and math.isfinite(c) for c in v)
            for v in vectors
        ):
            raise ConfigError(f"{source}: {key} must be a list of [x, y, z] vectors (one per sensor), got {value!r}")
        return tuple(tuple(float(c) for c in v) for v in vectors)
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, int | float) and not isinstance(value, bool)
        value = float(value) if ok else value
    else:
        ok = isinstance(value, str)
    if not ok:
        raise ConfigError(f"{source}: {key} must be {type(default).__name__}, got {value!r}")
    table, _, name = key.partition(".")
    if table == "profiles":  # [profiles.NAME] holds profile keys
        table, name = "profile", key.rsplit(".", 1)[1]
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if number and table in NAV_TABLES and (expected := nav_value_problem(table, name, value)) is not None:
        raise ConfigError(f"{source}: {key} must be {expected}, got {value!r}")  # NaN, inf, out of range
    return value


def defaults() -> Config:
    """The built-in configuration."""
    nav = NavConfig()
    values: dict[str, Setting] = {}
    for k, v in _SESSION_DEFAULTS.items():
        values[f"session.{k}"] = Setting(v, DEFAULT)
    for k, v in _UNIT_DEFAULTS.items():
        values[f"unit.{k}"] = Setting(v, DEFAULT)
    for k, v in _CALIBRATION_DEFAULTS.items():
        values[f"calibration.{k}"] = Setting(v, DEFAULT)
    for k in _FILTER_FIELDS:
        values[f"filter.{k}"] = Setting(getattr(nav, k), DEFAULT)
    for k in _DETECTOR_FIELDS:
        values[f"detector.{k}"] = Setting(getattr(nav.detector, k), DEFAULT)
    tof = TofConfig()
    for k in _TOF_KEYS:
        values[f"tof.{k}"] = Setting(getattr(tof, k), DEFAULT)
    profiles = {name: (p, "built-in") for name, p in PROFILES.items()}
    return Config(values, profiles)


def _apply_table(cfg: Config, data: dict[str, Any], source: str, where: str) -> None:
    for section in _SECTIONS:
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: [{section}] must be a table")
        for key, value in table.items():
            full = f"{section}.{key}"
            if full not in cfg.values:
                known = ", ".join(k.partition(".")[2] for k in cfg.values if k.startswith(section + "."))
                raise ConfigError(f"{where}: unknown key {key!r} in [{section}]; known: {known}")
            cfg.set(full, value, source)
    profiles = data.get("profiles", {})
    if not isinstance(profiles, dict):
        raise ConfigError(f"{where}: [profiles] must hold tables like [profiles.myshoe]")
    for name, table in profiles.items():
        if not isinstance(table, dict):
            raise ConfigError(f"{where}: [profiles.{name}] must be a table")
        base_name = table.get("base", "generic")
        if base_name not in cfg.profiles:
            raise ConfigError(
                f"{where}: [profiles.{name}] base {base_name!r} is not a known profile "
                f"({', '.join(sorted(cfg.profiles))})"
            )
        base = cfg.profiles[base_name][0]
        changes: dict[str, Any] = {"name": name}
        for key, value in table.items():
            if key == "base":
                continue
            if key not in _PROFILE_FIELDS:
                raise ConfigError(
                    f"{where}: unknown key {key!r} in [profiles.{name}]; known: base, {', '.join(_PROFILE_FIELDS)}"
                )
            changes[key] = _coerce(f"profiles.{name}.{key}", value, getattr(base, key), where)
        cfg.profiles[name] = (dataclasses.replace(base, **changes), f"{source} [profiles.{name}], base {base_name}")
    unknown = set(data) - {*_SECTIONS, "profiles"}
    if unknown:
        raise ConfigError(
            f"{where}: unknown section(s) {', '.join(sorted(unknown))}; known: {', '.join(_SECTIONS)}, profiles"
        )


def load_config(path: Path | None = None, *, cwd: Path | None = None) -> Config:
    """Defaults, then ``path`` (which must exist) or else ``footnav.toml`` in ``cwd`` if there is one.

    Raises
    ------
    ConfigError
        The file cannot be read, is not TOML, or holds an unknown key or a wrong type.
    """
    cfg = defaults()
    file = path if path is not None else (cwd or Path.cwd()) / DEFAULT_FILE
    if path is None and not file.is_file():
        return cfg
    try:
        data = tomllib.loads(file.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"cannot read the configuration file {file}: {exc.strerror or exc}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{file} is not valid TOML: {exc}") from exc
    except UnicodeDecodeError:
        raise ConfigError(f"{file} is not a text file; expected a TOML configuration file") from None
    _apply_table(cfg, data, f"file {file}", str(file))
    cfg.tof_config()  # one lever arm per viewing direction, none of them zero
    cfg.file = file
    return cfg


def apply_capture_settings(cfg: Config, nav_json: dict[str, Any], source: str) -> None:
    """Take the navigator settings recorded in a capture header (see :meth:`Config.to_json`)."""
    prof = nav_json.get("profile")
    if isinstance(prof, dict) and "name" in prof:
        try:
            up = UnitProfile(**prof)
        except TypeError:
            up = None
        if up is not None:
            name = str(prof["name"])
            if name not in cfg.profiles or cfg.profiles[name][0] != up:
                cfg.profiles[name] = (up, source)
            cfg.set("unit.profile", name, source)

    def recorded(key: str, value: Any, where: str) -> None:
        if cfg.source(key) != CLI:  # the command line still wins
            cfg.set(key, value, where)

    for section in ("filter", "detector", "tof"):
        table = nav_json.get(section, {})
        if isinstance(table, dict):
            for key, value in table.items():
                if f"{section}.{key}" in cfg.values:
                    recorded(f"{section}.{key}", value, source)
    filter_table = nav_json.get("filter")
    if isinstance(filter_table, dict) and "stance_levels" not in filter_table:
        # recorded before the stance height levels existed: its live estimates had none
        recorded("filter.stance_levels", False, f"{source} (recorded before stance levels)")
    if isinstance(filter_table, dict) and "gravity_mps2" not in filter_table:
        # recorded before gravity was configured: its live estimates took |f| at rest for gravity
        recorded("filter.gravity_mps2", 0.0, f"{source} (recorded before gravity_mps2)")
    if isinstance(filter_table, dict) and "step_smoothing" not in filter_table:
        # recorded before step smoothing existed: its live session had none
        recorded("filter.step_smoothing", False, f"{source} (recorded before step smoothing)")
