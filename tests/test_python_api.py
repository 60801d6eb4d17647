"""The Python API (``footnav.app``: navigate, read_recording, gait_parameters): the command line's code path,
its errors, pandas as an optional extra, and the user guide's worked example run as written."""

from __future__ import annotations

import doctest
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from footnav.app import Navigation, gait_parameters, navigate, read_recording
from footnav.app.api import navigation as api_module
from footnav.app.commands.export import EXPORT_COLUMNS, navigate_recording, run_export
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.device.files.recordings import Recording
from footnav.pipeline.errors import FootnavError

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "guide" / "python-api.md"


@pytest.fixture(scope="module")
def walk() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """30 s of the emulated foot at 200 Hz with a consumer IMU's errors: t, acc, gyr."""
    truth = simulate_walk("line", 30.0, rate_hz=200.0, seed=3)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, "mpu6500x4", seed=4)
    return truth.t_s, acc, gyr


def test_arrays_are_navigated_as_export_navigates_a_recording(walk, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    t, acc, gyr = walk
    result = navigate(acc, gyr, t, profile="mpu6500x4")
    rec = Recording("arrays", "arrays", t, acc, gyr, float(1.0 / np.median(np.diff(t))), "mpu6500x4")
    nav, _ = navigate_recording(rec)
    np.testing.assert_array_equal(result.pos_n_m, nav.pos_n_m)
    np.testing.assert_array_equal(result.quat_nb_wxyz, nav.quat_nb_wxyz)
    assert isinstance(result, Navigation) and result.profile == "mpu6500x4" and result.smooth is None
    # and as `footnav export` writes it, to the digits of its CSV
    csv = tmp_path / "walk.csv"
    np.savetxt(csv, np.column_stack([t, acc, gyr]), delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="")
    columns = "time=t:s,acc=ax;ay;az:m/s2,gyr=gx;gy;gz:rad/s,profile=mpu6500x4"
    run_export(csv, tmp_path / "track.csv", fmt=None, columns=columns, profile=None, smooth=None)
    exported = np.loadtxt(tmp_path / "track.csv", delimiter=",", skiprows=1)
    from_file = navigate(read_recording(csv, columns=columns))
    assert from_file.name == "walk" and from_file.profile == "mpu6500x4"
    table = from_file.to_pandas()
    assert tuple(table.columns) == EXPORT_COLUMNS and len(table) == len(t)
    np.testing.assert_allclose(table.to_numpy(dtype=float), exported, rtol=1e-8, atol=1e-12)


def test_smooth_true_is_the_whole_recording_smoother(walk) -> None:  # type: ignore[no-untyped-def]
    t, acc, gyr = walk
    whole = navigate(acc, gyr, t, profile="mpu6500x4", smooth=True)
    assert whole.smooth == "whole"
    np.testing.assert_array_equal(whole.pos_n_m, navigate(acc, gyr, t, profile="mpu6500x4", smooth="whole").pos_n_m)
    step = navigate(acc, gyr, t, profile="mpu6500x4", smooth="step")
    assert step.smooth == "step" and not np.array_equal(step.pos_n_m, whole.pos_n_m)
    # the smoothers' covariance is not the causal filter's growth: no turning-angle uncertainty
    assert np.isnan(gait_parameters(whole).turning_sd_rad).all()
    causal = gait_parameters(navigate(acc, gyr, t, profile="mpu6500x4"))
    assert len(causal) > 10 and np.isfinite(causal.turning_sd_rad).all()
    with pytest.raises(ValueError, match="smooth must be one of"):
        navigate(acc, gyr, t, smooth="rts")


def test_wrong_arguments_say_what_is_expected(walk) -> None:  # type: ignore[no-untyped-def]
    t, acc, gyr = walk
    with pytest.raises(FootnavError, match=r"expected acc_mps2 \(n, 3\), gyr_rads \(n, 3\) and t_s \(n,\)"):
        navigate(acc[:, :2], gyr, t)
    with pytest.raises(FootnavError, match="time runs backwards"):
        navigate(acc, gyr, t[::-1])
    with pytest.raises(FootnavError, match="known"):
        navigate(acc, gyr, t, profile="no-such-unit")
    with pytest.raises(TypeError, match="needs all three arrays"):
        navigate(acc, gyr)
    rec = Recording("r", "csv", t, acc, gyr, 200.0, "mpu6500x4")
    with pytest.raises(TypeError, match="leave out gyr_rads and t_s"):
        navigate(rec, gyr, t)
    moving = np.tile([0.0, 0.0, 9.8], (t.size, 1)) + np.sin(np.arange(t.size))[:, None]
    with pytest.raises(FootnavError, match="never still"):
        navigate(moving, gyr, t)


def test_read_recording_reads_what_the_commands_read(shared_data: Path, tmp_path: Path) -> None:
    rec = read_recording(shared_data / "pyshoe-vicon" / "2017-11-22-11-22-03.mat")
    assert rec.format == "pyshoe" and rec.profile == "gx3" and rec.gt_pos_m is not None
    assert read_recording(str(shared_data / "xio-gait-tracking" / "short_walk.csv")).format == "xio"
    assert read_recording(shared_data / "openshoe" / "data_inert.txt", format="openshoe").rate_hz == pytest.approx(
        250.0, rel=0.01
    )
    bad = tmp_path / "photo.jpg"
    bad.write_bytes(b"\xff\xd8\xff\xe0garbage")
    with pytest.raises(FootnavError, match="or a footnav capture"):
        read_recording(bad)


def test_to_pandas_without_pandas_names_the_extra(walk, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    t, acc, gyr = walk
    result = navigate(acc[:400], gyr[:400], t[:400])
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas raises ImportError
    with pytest.raises(ImportError, match=re.escape("pip install 'footnav[pandas]'")):
        result.to_pandas()


def test_the_docstring_examples_run() -> None:
    outcome = doctest.testmod(api_module)
    assert outcome.attempted >= 5 and outcome.failed == 0


def _python_blocks(markdown: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```$", markdown, flags=re.MULTILINE | re.DOTALL)


def test_the_user_guide_example_runs_as_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """docs/guide/python-api.md, its ``python`` blocks run in order in one namespace, as a notebook runs
    them: the API, the gait parameters, the plot (a Rerun recording) and two feet, whose printed errors
    are the page's."""
    guide = GUIDE.read_text(encoding="utf-8")
    blocks = _python_blocks(guide)
    assert len(blocks) >= 9
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {"__name__": "__guide__"}
    for k, block in enumerate(blocks):
        exec(compile(block, f"{GUIDE.name}, python block {k + 1}", "exec"), namespace)
    strides = namespace["strides"]
    truth = namespace["truth"]
    assert len(strides) >= 40  # type: ignore[arg-type]
    lengths = strides.length_m  # type: ignore[attr-defined]
    assert 1.2 < float(np.mean(lengths)) < 1.6 and (tmp_path / "gait.rrd").stat().st_size > 1000
    result = namespace["result"]
    end_error = np.linalg.norm(result.pos_n_m[-1] - truth.pos_n_m[-1])  # type: ignore[attr-defined]
    assert end_error < 0.05
    pair_error_m = namespace["pair_error_m"]
    assert np.mean(pair_error_m["coupled"]) < np.mean(pair_error_m["independent"])  # type: ignore[index]
    apart_m = namespace["apart_m"]  # the feet in one frame: 0.2 m apart at the start, a step apart walking
    assert abs(apart_m[0] - 0.2) < 0.005 and 0.4 < np.median(apart_m) < 0.7  # type: ignore[index, call-overload]
    shown = re.search(r"^```text\n(coupled .*?)^```$", guide, flags=re.MULTILINE | re.DOTALL)
    assert shown is not None and shown.group(1) in capsys.readouterr().out


def test_the_api_is_importable_from_an_installed_footnav_without_numerics() -> None:
    """From another folder: ``footnav.app`` names the API, and importing it loads no numerics."""
    code = (
        "import sys, footnav.app as app\n"
        "print(sorted(n for n in ('navigate', 'read_recording', 'gait_parameters', 'Navigation') if n in app.__all__),"
        " 'numpy' in sys.modules)\n"
        "print(app.navigate.__module__)"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run([sys.executable, "-c", code], cwd="/", capture_output=True, text=True, check=True, env=env)
    assert out.stdout.split("\n")[:2] == [
        "['Navigation', 'gait_parameters', 'navigate', 'read_recording'] False",
        "footnav.app.api.navigation",
    ]
