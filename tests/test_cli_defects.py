"""Issue 28: the user's commands that ended in a traceback, a wrong summary, an ignored option or a
misleading message, run as the user ran them: exit code and the one line the user reads."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from footnav.device.emulator.motion.gait import SPEED_RANGE_MPS, simulate_walk
from footnav.device.emulator.serving.pty import PtyShoeServer
from test_cli_errors import _assert_one_line_error, _footnav
from test_fuzz_inputs import demo_capture, rewrite_capture

ENV = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}


def _usage_error(proc: subprocess.CompletedProcess[str], *needles: str) -> str:
    """The argparse error line, checked: exit code 2, no traceback, the usage printed."""
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and "usage:" in proc.stderr
    (line,) = [ln for ln in proc.stderr.splitlines() if ": error: " in ln]
    for needle in needles:
        assert needle in line
    return line


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3-s demo's capture (no ToF)."""
    path = tmp_path_factory.mktemp("capture") / "demo.mcap"
    path.write_bytes(demo_capture())
    return path


# ------------------------------------------------------------------ 1. tracebacks


def test_a_walking_speed_outside_the_gait_model_is_a_usage_error() -> None:
    line = _usage_error(_footnav("demo", "--speed", "1.0"), "--speed", "1.2 to 1.8 m/s", "'1.0'")
    assert "ValueError" not in line


def test_a_demo_longer_than_memory_allows_is_a_usage_error_that_says_why() -> None:
    _usage_error(_footnav("demo", "--duration", "1e9"), "--duration", "at most 3600 s", "memory", "'1e9'")


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--dual-imu", "--feet", "2"], "the dual-IMU demo emulates one shoe"),
        (["--miscalibrated", "--axis-errors", "gyro-bias-calibrated"], "drop --axis-errors"),
    ],
)
def test_demo_options_the_emulator_cannot_serve_are_one_line(args: list[str], said: str, tmp_path: Path) -> None:
    """Found by the command-line fuzzer (tests/test_fuzz_cli.py): these were ``ValueError`` tracebacks."""
    _assert_one_line_error(_footnav("demo", *args, "--no-viewer", "--sessions", str(tmp_path)), said)


def test_a_misspelled_option_gets_its_commands_usage_and_the_closest_option() -> None:
    proc = _footnav("export", "walk.csv", "--colums", "time=ts:ms", "-o", "x.csv")
    assert proc.returncode == 2 and proc.stderr.startswith("usage: footnav export "), proc.stderr
    assert proc.stderr.splitlines()[-1] == (
        "footnav export: error: unrecognized arguments: --colums time=ts:ms; --colums: did you mean --columns?"
    )
    proc = _footnav("replay", "walk.csv", "--foo")
    assert proc.stderr.splitlines()[-1] == "footnav replay: error: unrecognized arguments: --foo"  # nothing close


def test_the_parser_knows_the_speeds_the_gait_model_covers() -> None:
    from footnav.app.parser import WALKING_SPEED_MPS

    assert WALKING_SPEED_MPS == SPEED_RANGE_MPS


# ------------------------------------------------------------------ 2. Ctrl-C


def _interrupt_after(proc: subprocess.Popen[str], ready: Path | str, *, then_s: float = 1.0) -> tuple[str, str]:
    """SIGINT to ``proc`` ``then_s`` after ``ready`` (a file that has grown, or a line on stderr)."""
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(proc.stderr.readline, "")), daemon=True)  # type: ignore[union-attr]
    reader.start()
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if isinstance(ready, Path) and sum(f.stat().st_size for f in ready.rglob("*.mcap")) > 20_000:
            break
        if isinstance(ready, str) and any(ready in ln for ln in lines):
            break
        time.sleep(0.1)
    assert proc.poll() is None, "".join(lines)
    time.sleep(then_s)
    proc.send_signal(signal.SIGINT)
    out = proc.stdout.read()  # type: ignore[union-attr]
    proc.wait(60)
    reader.join(10)
    return out, "".join(lines)


def _popen(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "footnav.app", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV
    )


def test_ctrl_c_in_live_exits_130(tmp_path: Path) -> None:
    walk = simulate_walk("rectangle", 60.0, seed=1)
    with PtyShoeServer(walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, record=False) as server:
        proc = _popen("live", "--port", server.port, "--no-viewer", "--sessions", str(tmp_path))
        _, err = _interrupt_after(proc, tmp_path)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "stopped: the unit was told to stop" in err


def test_ctrl_c_in_replay_exits_130(capture: Path) -> None:
    proc = _popen("replay", str(capture), "--speed", "0.05x", "--no-viewer")  # 20 times slower than captured
    out, err = _interrupt_after(proc, "replaying")
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    assert "samples navigated" in out


def test_the_summary_counts_the_distance_walked_up_to_the_last_sample() -> None:
    from footnav.app.commands.demo import DemoSummary, distance_walked_m

    walk = simulate_walk("rectangle", 30.0, seed=1)
    assert distance_walked_m(walk, walk.t_s.size - 1) == pytest.approx(walk.distance_m, rel=1e-12)
    at_9s = distance_walked_m(walk, 9000)
    assert 0.05 * walk.distance_m < at_9s < 0.5 * walk.distance_m
    assert distance_walked_m(walk, 500) == 0.0  # still standing
    lines = DemoSummary(at_9s, 0.01, walk.t_s.size, 9000, 0, interrupted=True).lines()
    assert f"distance walked:   {at_9s:.2f} m (ground truth, up to the last sample navigated)" in lines


# ------------------------------------------------------------------ 3. options ignored


def test_columns_for_a_recording_whose_columns_are_known_is_refused(tmp_path: Path, shared_data: Path) -> None:
    walk = shared_data / "xio-gait-tracking" / "short_walk.csv"
    proc = _footnav("export", str(walk), "-o", str(tmp_path / "t.csv"), "--columns", "time=foo")
    _assert_one_line_error(proc, "is an x-io CSV", "--columns applies to a generic CSV only", "--format csv")
    assert not (tmp_path / "t.csv").exists()
    proc = _footnav("export", str(walk), "-o", str(tmp_path / "t.csv"), "--columns", "time=foo", "--format", "csv")
    _assert_one_line_error(proc, "column", "foo", "not found", "Time (s)")  # used: its column is looked for


def _track(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1)


def test_a_capture_without_tof_is_exported_smoothed(capture: Path, tmp_path: Path) -> None:
    causal, whole, step = tmp_path / "causal.csv", tmp_path / "whole.csv", tmp_path / "step.csv"
    proc = _footnav("export", str(capture), "-o", str(causal))
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr  # no replay notes or progress lines in a log
    proc = _footnav("export", str(capture), "-o", str(whole), "--smooth")
    assert proc.returncode == 0, proc.stderr
    assert "RTS-smoothed" in proc.stdout
    proc = _footnav("export", str(capture), "-o", str(step), "--step-smoothing", "--steps", str(tmp_path / "s.csv"))
    assert proc.returncode == 0, proc.stderr
    c, w, s = _track(causal), _track(whole), _track(step)
    assert c.shape == w.shape == s.shape and np.array_equal(c[:, 0], w[:, 0])  # the same samples
    # the smoothers run over the samples the live session navigated, with its settings: the RTS
    # pass ends on the causal estimate, and differs from it before
    np.testing.assert_allclose(w[-1, 1:4], c[-1, 1:4], atol=1e-6)
    assert 0 < np.abs(w[:, 1:4] - c[:, 1:4]).max() < 0.05
    assert 0 < np.abs(s[:, 1:4] - c[:, 1:4]).max() < 0.05


def test_a_tof_capture_is_not_smoothed(tmp_path: Path) -> None:
    proc = _footnav("demo", "--tof", "--duration", "3", "--pace", "max", "--no-viewer", "--sessions", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    (tof,) = tmp_path.glob("*.mcap")
    proc = _footnav("export", str(tof), "-o", str(tmp_path / "t.csv"), "--smooth")
    _assert_one_line_error(proc, "ToF", "the smoothers do not take the ToF channel")


# ------------------------------------------------------------------ 4. messages


def test_evaluate_says_a_capture_has_no_ground_truth(capture: Path) -> None:
    proc = _footnav("evaluate", str(capture))
    _assert_one_line_error(proc, "nothing evaluated: the recording could not be measured")
    assert "is a footnav capture: it records no ground truth" in proc.stderr
    assert "unknown recording format" not in proc.stderr
    assert proc.stdout == ""  # no empty table
    proc = _footnav("evaluate", "--left", str(capture), "--right", str(capture))  # as a pair: the same reason
    _assert_one_line_error(proc, f"{capture} is a footnav capture: it records no ground truth")
    assert proc.stdout == ""


def test_evaluate_names_the_missing_feet(capture: Path) -> None:
    proc = _footnav("evaluate", "--left", str(capture))
    _assert_one_line_error(proc, "two feet are evaluated as --left FILE --right FILE")
    assert "(--right is missing)" in proc.stderr
    proc = _footnav("evaluate", "--independent-feet", str(capture))
    _assert_one_line_error(proc, "two feet are evaluated as --left FILE --right FILE")
    assert "(--left and --right are missing)" in proc.stderr


def test_evaluate_with_every_file_skipped_says_so(tmp_path: Path) -> None:
    (tmp_path / "a.csv").write_text("")
    (tmp_path / "b.csv").write_text("t,ax\n1,2\n")
    proc = _footnav("evaluate", str(tmp_path / "a.csv"), str(tmp_path / "b.csv"))
    _assert_one_line_error(proc, "nothing evaluated: none of the 2 recordings could be measured")
    assert len([ln for ln in proc.stderr.splitlines() if ln.startswith("footnav: skipped:")]) == 2
    assert proc.stdout == ""


@pytest.mark.parametrize(
    ("content", "said"), [(" \n", "is empty"), ("\n\nt,ax,ay,az,gx,gy,gz\n", "starts with a blank")]
)
def test_an_empty_csv_is_called_empty(tmp_path: Path, content: str, said: str) -> None:
    path = tmp_path / "walk.csv"
    path.write_text(content)
    proc = _footnav("export", str(path), "-o", str(tmp_path / "t.csv"))
    _assert_one_line_error(proc, said, "header row")
    assert "the header has" not in proc.stderr


def test_a_csv_without_the_default_columns_says_how_to_read_it(tmp_path: Path) -> None:
    from footnav.device.files.recordings import CsvMapping, InputFormatError, load_recording

    path = tmp_path / "walk.csv"
    path.write_text("ts,ax,ay,az,gx,gy,gz\n0,0,0,9.8,0,0,0\n")
    with pytest.raises(InputFormatError, match=r"column t not found; .* name its columns and units with --columns"):
        load_recording(path)
    with pytest.raises(InputFormatError, match=r"column tt not found; the header has ts, ax, ay, az, gx, gy, gz$"):
        load_recording(path, mapping=CsvMapping.parse("time=tt"))  # --columns given: its names are wrong
    path.write_text("t;ax;ay;az;gx;gy;gz\n0;0;0;9.8;0;0;0\n")
    with pytest.raises(InputFormatError, match=r"separated by ';' \(header t;ax.*footnav reads comma-separated CSV"):
        load_recording(path)


def test_a_live_session_that_never_got_data_leaves_no_empty_recording(tmp_path: Path) -> None:
    """Without a display the session saves to a default file; no unit answered: it is removed, and two
    failed feet print no coupling summary."""
    env = {**os.environ, "DISPLAY": "", "WAYLAND_DISPLAY": ""}
    for ports in (["--port", "/dev/ttyNOPE42"], ["--left", "/dev/ttyNOPE42", "--right", "/dev/ttyNOPE43"]):
        proc = subprocess.run(
            [sys.executable, "-m", "footnav.app", "live", *ports, "--sessions", str(tmp_path / "s")],
            capture_output=True, text=True, timeout=60, env=env, cwd=tmp_path, check=False,
        )  # fmt: skip
        _assert_one_line_error(proc, "/dev/ttyNOPE42", "plugged in")
        assert "saving to" in proc.stderr and "the empty recording" in proc.stderr
        assert list(tmp_path.glob("*.rrd")) == [] and list((tmp_path / "s").glob("*.mcap")) == []
        assert "feet coupled" not in proc.stdout


def test_a_rerun_recording_is_told_apart_from_a_recording_to_navigate(tmp_path: Path) -> None:
    import rerun as rr

    path = tmp_path / "walk.rrd"
    rec = rr.RecordingStream("footnav-test")
    rec.save(str(path))
    rec.log("points", rr.Points3D([[0.0, 0.0, 0.0]]))
    rec.disconnect()
    proc = _footnav("replay", str(path), "--no-viewer")
    _assert_one_line_error(proc, "is a Rerun recording (.rrd)", f"open it with `rerun {path}`")


def test_a_mat_file_that_is_not_a_pyshoe_trial_says_what_reads_it(tmp_path: Path) -> None:
    path = tmp_path / "x.mat"
    scipy.io.savemat(path, {"acc": np.zeros((5, 3)), "time": np.arange(5.0)})
    proc = _footnav("replay", str(path), "--no-viewer")
    _assert_one_line_error(proc, "is not a PyShoe trial", "fields ts", "imu", "this one has acc, time")


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["demo", "--speed", "abc"], "argument --speed: expected a walking speed from 1.2 to 1.8 m/s"),
        (["demo", "--pace", "zz"], "argument --pace: expected 1x, Nx (N > 0) or max, got 'zz'"),
        (["calibrate", "--demo", "--imu-mask", "zz"], "argument --imu-mask: expected an IMU mask"),
        (["scan", "--timeout", "abc"], "argument --timeout: expected a positive number, got 'abc'"),
        (["replay", "x.mcap", "--start", "abc"], "argument --start: expected a time in seconds"),
        (["demo", "--lever-arm", "0", "nan", "0"], "argument --lever-arm: expected a finite number, got 'nan'"),
    ],
)
def test_argument_errors_say_what_was_expected(args: list[str], said: str) -> None:
    line = _usage_error(_footnav(*args), said)
    assert "invalid" not in line and "<lambda>" not in line and "_p" not in line


def test_a_calibration_that_cannot_start_leaves_no_capture(tmp_path: Path) -> None:
    proc = _footnav("calibrate", "--port", "/dev/ttyUSB9-footnav-test", "--sessions", str(tmp_path))
    _assert_one_line_error(proc, "no such port")
    assert list(tmp_path.rglob("*")) == []


@pytest.mark.parametrize("command", ["demo", "replay"])
def test_save_where_nothing_can_be_written_is_refused_before_starting(
    command: str, capture: Path, tmp_path: Path
) -> None:
    args = ["--duration", "2", "--pace", "max", "--sessions", str(tmp_path)] if command == "demo" else [str(capture)]
    proc = _footnav(command, *args, "--no-viewer", "--save", "/proc/footnav-test.rrd")
    _assert_one_line_error(proc, "cannot write the recording to /proc/footnav-test.rrd")
    assert "samples navigated" not in proc.stdout  # nothing ran
    assert list(tmp_path.iterdir()) == []  # no capture either


def test_the_save_check_leaves_nothing_behind(tmp_path: Path) -> None:
    from footnav.pipeline.errors import FootnavError
    from footnav.views.outputs import check_save_destination

    check_save_destination(tmp_path / "new" / "folders" / "walk.rrd")
    assert list(tmp_path.iterdir()) == []
    kept = tmp_path / "kept.rrd"
    kept.write_bytes(b"recording")
    check_save_destination(kept)
    assert kept.read_bytes() == b"recording"
    with pytest.raises(FootnavError, match="it is a folder"):
        check_save_destination(tmp_path)


def test_dev_null_is_not_a_serial_port(tmp_path: Path) -> None:
    proc = _footnav("live", "--port", "/dev/null", "--no-viewer", "--sessions", str(tmp_path))
    _assert_one_line_error(proc, "/dev/null is not a serial port")
    assert "ioctl" not in proc.stderr


# ------------------------------------------------------------------ 5. untrusted capture metadata


def _edited(capture: Path, tmp_path: Path, **changes: object) -> Path:
    """The capture with these unit header fields changed (``settings`` keys, or ``foot``)."""
    out = tmp_path / "edited.mcap"

    def edit(name: str, md: dict[str, str]) -> dict[str, str]:
        if name != "footnav.unit":
            return md
        settings = json.loads(md["settings"])
        settings.update({k: v for k, v in changes.items() if k != "foot"})
        return {**md, "settings": json.dumps(settings), "foot": str(changes.get("foot", md["foot"]))}

    rewrite_capture(capture, out, edit)
    return out


@pytest.mark.parametrize("command", ["export", "replay"])
def test_a_capture_setting_of_the_wrong_type_is_named(command: str, capture: Path, tmp_path: Path) -> None:
    edited = _edited(capture, tmp_path, rate_hz="abc")
    args = ["-o", str(tmp_path / "t.csv")] if command == "export" else ["--no-viewer"]
    proc = _footnav(command, str(edited), *args)
    _assert_one_line_error(proc, "capture metadata: unit 'foot': rate_hz is 'abc', expected a positive number")


@pytest.mark.parametrize(
    ("changes", "said"),
    [
        ({"mode": "warp"}, "mode is 'warp', expected one of normal_imu"),
        ({"rate_divider_log2": 15}, "rate_divider_log2 is 15, expected a whole number from 0 to 14"),
        ({"stance": 3}, "stance is 3, expected one of inertial, height, and, or"),
        ({"dual_imu_lever_b_m": [0.01, "x", 0]}, "dual_imu_lever_b_m is [0.01, 'x', 0], expected a list of 3"),
        ({"fused_imu_mask": 0}, "fused_imu_mask is 0, expected a whole number from 1 to 15"),
        ({"nav_config": {"detector": {"history_s": 1e9}}}, "nav_config.detector.history_s is 1000000000.0"),
        ({"nav_config": {"profile": {"name": "x", "zupt_sigma_mps": "a"}}}, "nav_config.profile.zupt_sigma_mps"),
    ],
)
def test_capture_settings_are_checked_against_the_schema(
    changes: dict[str, object], said: str, capture: Path, tmp_path: Path
) -> None:
    proc = _footnav("export", str(_edited(capture, tmp_path, **changes)), "-o", str(tmp_path / "t.csv"))
    _assert_one_line_error(proc, "capture metadata", said)


def test_a_foot_name_never_becomes_a_path(capture: Path, tmp_path: Path) -> None:
    work = tmp_path / "a" / "b" / "c"
    work.mkdir(parents=True)
    edited = _edited(capture, work, foot="../../../x")
    proc = _footnav("export", str(edited), "-o", str(work / "t.csv"))
    _assert_one_line_error(proc, "capture metadata: foot is '../../../x'", "letters, digits")
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["edited.mcap"]


@pytest.mark.parametrize(
    ("times", "said"),
    [
        (np.arange(400) * 1e-300, "give 1e+300 samples a second"),
        (np.where(np.arange(400) == 7, np.nan, np.arange(400) / 100), "time stamp nan at data row 8"),
        (np.arange(400)[::-1] / 100, "time runs backwards at data row 2"),
    ],
)
def test_absurd_csv_times_are_refused(times: np.ndarray, said: str, tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    imu = np.column_stack(
        [rng.normal(0, 0.05, (400, 2)), 9.81 + rng.normal(0, 0.05, 400), rng.normal(0, 0.01, (400, 3))]
    )
    path = tmp_path / "walk.csv"
    rows = [",".join(repr(float(v)) for v in (t, *r)) for t, r in zip(times, imu, strict=True)]
    path.write_text("t,ax,ay,az,gx,gy,gz\n" + "\n".join(rows) + "\n")
    proc = _footnav("export", str(path), "-o", str(tmp_path / "t.csv"))
    _assert_one_line_error(proc, said)
