"""Configuration: defaults < footnav.toml < command line, with sources; bad files are clear errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from footnav.app.config import CLI, ConfigError, apply_capture_settings, defaults, load_config
from footnav.pipeline.aiding.tof_types import TofConfig
from footnav.pipeline.navigation.navigator import NavConfig
from footnav.pipeline.navigation.profiles import PROFILES

TOML = """
[session]
sessions_dir = "caps"

[unit]
profile = "myshoe"

[filter]
align_s = 0.8

[detector]
threshold = 30

[profiles.myshoe]
base = "adis16367"
gyr_bias_init_radps = 0.003

[tof]
lever_b_m = [[0.15, 0.0, 0.02], [-0.08, -0.03, 0.03]]
dir_b = [[0.2, 0, -1], [0, 0, -1]]
"""


def test_file_and_command_line_override_defaults_with_sources(tmp_path: Path) -> None:
    (tmp_path / "footnav.toml").write_text(TOML)
    cfg = load_config(cwd=tmp_path)
    assert cfg.file == tmp_path / "footnav.toml"
    assert cfg["filter.align_s"] == 0.8 and cfg.source("filter.align_s").startswith("file ")
    assert cfg["detector.threshold"] == 30.0 and isinstance(cfg["detector.threshold"], float)
    assert cfg.source("filter.dt_max_s") == "default"
    nav = cfg.nav_config()
    assert isinstance(nav, NavConfig) and nav.align_s == 0.8 and nav.detector.threshold == 30.0
    assert nav.profile.name == "myshoe" and nav.profile.gyr_bias_init_radps == 0.003
    assert nav.profile.acc_noise_mps2_rthz == PROFILES["adis16367"].acc_noise_mps2_rthz  # from the base
    cfg.set("unit.profile", "gx3", CLI)
    assert cfg.profile() is PROFILES["gx3"] and cfg.source("unit.profile") == CLI
    assert load_config(cwd=tmp_path / "nowhere").source("filter.align_s") == "default"


def test_tof_mounting_from_the_file_and_through_a_capture_header(tmp_path: Path) -> None:
    (tmp_path / "footnav.toml").write_text(TOML)
    cfg = load_config(cwd=tmp_path)
    tof = cfg.tof_config("and")
    assert tof.lever_b_m == ((0.15, 0.0, 0.02), (-0.08, -0.03, 0.03)) and tof.dir_b[0] == (0.2, 0.0, -1.0)
    assert tof.detector.mode == "and" and tof.sigma_range_m == TofConfig().sigma_range_m
    assert cfg.source("tof.dir_b").startswith("file ") and cfg.source("tof.sigma_range_m") == "default"
    # what a capture header records is what its replay navigates with
    replay = defaults()
    apply_capture_settings(replay, json.loads(json.dumps(cfg.to_json())), "capture x.mcap")
    assert replay.tof_config() == cfg.tof_config() and replay.source("tof.lever_b_m") == "capture x.mcap"
    with pytest.raises(ConfigError, match="unknown stance detector 'both'"):
        cfg.tof_config("both")


def test_a_capture_recorded_before_the_stance_levels_replays_without_them() -> None:
    """Its live estimates had no stance levels, so its replay has none either (replay equals live)."""
    recorded = defaults().to_json()
    assert recorded["filter"]["stance_levels"] is True
    del recorded["filter"]["stance_levels"]
    replay = defaults()
    apply_capture_settings(replay, recorded, "capture old.mcap")
    assert replay.nav_config().stance_levels is False
    assert "before stance levels" in replay.source("filter.stance_levels")
    now = defaults()
    apply_capture_settings(now, defaults().to_json(), "capture new.mcap")
    assert now.nav_config().stance_levels is True


def test_a_capture_recorded_before_gravity_was_configured_replays_with_the_gravity_it_measured() -> None:
    """Its live estimates took |f| at rest for gravity (``NavConfig.gravity_mps2`` ≤ 0), so its replay
    does too; a capture of today replays with the gravity it recorded."""
    recorded = defaults().to_json()
    assert recorded["filter"]["gravity_mps2"] == 9.80665
    del recorded["filter"]["gravity_mps2"]
    replay = defaults()
    apply_capture_settings(replay, recorded, "capture old.mcap")
    assert replay.nav_config().gravity_mps2 == 0.0
    assert "before gravity_mps2" in replay.source("filter.gravity_mps2")
    now = defaults()
    apply_capture_settings(now, defaults().to_json(), "capture new.mcap")
    assert now.nav_config().gravity_mps2 == 9.80665


def test_step_smoothing_replays_as_recorded_unless_the_command_line_says() -> None:
    """A capture replays with the step smoothing its session had (none before it existed); the
    command line's ``--step-smoothing`` wins over the capture, as over the file."""
    on = defaults()
    on.set("filter.step_smoothing", True, "file footnav.toml")
    replay = defaults()
    apply_capture_settings(replay, on.to_json(), "capture new.mcap")
    assert replay.nav_config().step_smoothing is True
    old = defaults().to_json()
    del old["filter"]["step_smoothing"]
    replay = defaults()
    replay.set("filter.step_smoothing", True, "file footnav.toml")
    apply_capture_settings(replay, old, "capture old.mcap")
    assert replay.nav_config().step_smoothing is False
    assert "before step smoothing" in replay.source("filter.step_smoothing")
    asked = defaults()
    asked.set("filter.step_smoothing", True, CLI)
    apply_capture_settings(asked, old, "capture old.mcap")
    apply_capture_settings(asked, defaults().to_json(), "capture new.mcap")
    assert asked.nav_config().step_smoothing is True and asked.source("filter.step_smoothing") == CLI


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("[filter]\nalign = 1\n", "unknown key 'align' in [filter]"),
        ("[detector]\nthreshold = 'high'\n", "detector.threshold must be float"),
        ("[profiles.x]\nbase = 'nope'\n", "base 'nope' is not a known profile"),
        ("[viewer]\nx = 1\n", "unknown section"),
        ("[filter\n", "not valid TOML"),
        ("[tof]\nlever_b_m = [[0.1, 0.0]]\n", "tof.lever_b_m must be a list of [x, y, z] vectors"),
        ("[tof]\nlever_b_m = [[0.1, 0.0, 0.0]]\n", "[tof] has 1 lever arms"),
        ("[tof]\ndir_b = [[0, 0, 0], [0, 0, -1], [0, 0, -1]]\n", "a viewing direction is zero"),
    ],
)
def test_bad_files_say_what_is_wrong(tmp_path: Path, text: str, needle: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_config(path)
    assert needle in str(err.value) and str(path) in str(err.value)


def test_config_command_shows_values_and_sources(tmp_path: Path) -> None:
    (tmp_path / "footnav.toml").write_text(TOML)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "config", "--rate-divider", "2"],
        capture_output=True, text=True, cwd=tmp_path, env=env, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = proc.stdout
    assert "[filter]" in out and "[detector]" in out and "[profiles.myshoe]" in out and "[tof]" in out
    line = next(x for x in out.splitlines() if x.startswith("lever_b_m = "))
    assert "[[0.15, 0.0, 0.02], [-0.08, -0.03, 0.03]]" in line and "file " in line  # as TOML
    line = next(x for x in out.splitlines() if x.startswith("align_s = "))
    assert "0.8" in line and "file " in line
    line = next(x for x in out.splitlines() if x.startswith("rate_divider = "))
    assert "2" in line and "command line" in line
    line = next(x for x in out.splitlines() if x.startswith("dt_max_s = "))
    assert line.rstrip().endswith("# default")
    bad = subprocess.run(
        [sys.executable, "-m", "footnav.app", "config", "--config", str(tmp_path / "missing.toml")],
        capture_output=True, text=True, env=env, check=False,
    )  # fmt: skip
    assert bad.returncode == 2 and "cannot read the configuration file" in bad.stderr


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ("[detector]\nthreshold = nan\n", r"detector\.threshold must be a number from 1e-09 to 1e\+12, got nan"),
        ("[detector]\nthreshold = inf\n", r"detector\.threshold must be a number from 1e-09 to 1e\+12, got inf"),
        ("[filter]\nalign_s = -5\n", r"filter\.align_s must be a number over 0, up to 600, got -5"),
        (
            '[profiles.x]\nbase = "generic"\nacc_noise_mps2_rthz = nan\n',
            r"profiles\.x\.acc_noise_mps2_rthz must be a number from 0 to 1e\+06, got nan",
        ),
    ],
)
def test_the_navigators_numbers_must_be_finite_and_in_range(tmp_path: Path, toml: str, message: str) -> None:
    """The ranges a capture's header is checked against hold for footnav.toml too (before: NaN, inf and
    a negative alignment time were taken; with inf the final error was 1.23 % instead of 0.08 %)."""
    path = tmp_path / "footnav.toml"
    path.write_text(toml)
    with pytest.raises(ConfigError, match=message):
        load_config(path).profile()
