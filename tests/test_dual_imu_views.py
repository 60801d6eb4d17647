"""The dual-IMU recording: ``footnav experiment dual-imu --save`` writes each IMU's track, the fused
tracks, truth and the constraint residuals; read back from the real .rrd file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from footnav.app.cli import main
from footnav.app.experiments.dual_imu import BOARD_METHODS, METHODS, evaluate_run, view_of
from footnav.views.dual_imu import AXES, save_dual_runs
from footnav.views.paths import TIMELINE, DualPaths
from rerun.chunk import RrdReader


def _rows(path: Path, entity: str) -> int:
    store = RrdReader(path).stream().collect()
    return int(store.reader(index=TIMELINE, contents=[f"/{entity}"]).to_arrow_table().num_rows)


def test_saved_run_holds_every_track_and_residual(tmp_path: Path) -> None:
    run = evaluate_run("stairs", 2)
    view = view_of(run)
    out = tmp_path / "dual.rrd"
    save_dual_runs(out, {"stairs": view}, track_every=10)
    assert out.stat().st_size > 10_000
    paths = DualPaths("stairs")
    n = len(view.t_s)
    for method in BOARD_METHODS:
        finite = np.all(np.isfinite(view.tracks_n_m[method][::10]), axis=1)
        assert _rows(out, paths.track(method)) == int(finite.sum())
    assert _rows(out, paths.imu("imu1")) == _rows(out, paths.imu("imu2")) == len(range(0, n, 10))
    assert _rows(out, paths.truth) == len(range(0, n, 10))
    for name, values in view.residuals.items():
        formed = int(np.all(np.isfinite(values), axis=1).sum())
        assert formed > 100
        for axis in AXES:
            assert _rows(out, paths.residual(name, axis)) == formed


def test_run_names_must_be_plain() -> None:
    with pytest.raises(ValueError, match="plain identifier"):
        DualPaths("a/b")


def test_experiment_command_prints_one_table_and_saves(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "exp.rrd"
    assert main(["experiment", "dual-imu", "--seeds", "1", "--first-seed", "5", "--save", str(out)]) == 0
    text = capsys.readouterr().out
    for course in ("rectangle", "stairs"):
        for method in METHODS:
            assert f"{course:<10} {method:<9}" in text
    assert "mean/single" in text and "mean/classic" in text and out.exists()
    assert _rows(out, DualPaths("rectangle").track("footnav")) > 0
