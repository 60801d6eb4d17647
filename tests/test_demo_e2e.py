"""``footnav demo`` end to end: emulator -> pty -> real serial code -> pipeline -> .rrd, read back."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest
from rerun.chunk import RrdReader

N_SAMPLES = 60_000  # 60 s at 1 kHz


def _run_demo(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    return subprocess.run(
        [sys.executable, "-m", "footnav.app", "demo", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        check=False,
    )


def _column(tbl: pa.Table, name: str) -> np.ndarray:
    return pc.list_flatten(tbl[name]).to_numpy(zero_copy_only=False)


@pytest.fixture(scope="module")
def demo_rrd(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    path = tmp_path_factory.mktemp("demo") / "demo.rrd"
    proc = _run_demo(
        "--path", "rectangle", "--duration", "60", "--save", str(path), "--pace", "max", "--sessions", str(path.parent),
        "--step-smoothing",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return path, proc.stdout + proc.stderr


def test_demo_reports_error_within_one_percent(demo_rrd: tuple[Path, str]) -> None:
    _, output = demo_rrd
    assert "no display" in output and "rerun " in output  # says where the file is and how to view it
    m = re.search(r"samples navigated: (\d+) of (\d+) \(lost packets: (\d+)\)", output)
    assert m and int(m[1]) == int(m[2]) == N_SAMPLES and int(m[3]) == 0
    dist = float(re.search(r"distance walked:\s+([\d.]+) m", output)[1])  # type: ignore[index]
    err_pct = float(re.search(r"= ([\d.]+) % of distance", output)[1])  # type: ignore[index]
    assert 60 < dist < 110  # 60 s at 1.4 m/s with a still start and end
    assert err_pct <= 1.0


def test_recording_holds_every_sample_on_one_timeline(demo_rrd: tuple[Path, str]) -> None:
    path, _ = demo_rrd
    reader = RrdReader(path)
    assert [r.application_id for r in reader.recordings()] == ["footnav"]
    assert reader.blueprints(), "the default blueprint travels with the file"
    store = reader.stream().collect()
    entities = {
        "track": "/world/foot/track",
        "stance": "/plots/stance/foot",
        "clearance": "/plots/clearance/foot",
        "sigma": "/plots/pos_sigma/foot",
        "truth": "/world/truth/foot",
    }
    tables = {k: store.reader(index="imu_time", contents=[e]).to_arrow_table() for k, e in entities.items()}
    for key in ("track", "stance", "clearance", "sigma", "truth"):
        assert tables[key].num_rows == N_SAMPLES, key
    track = np.array(tables["track"]["/world/foot/track:Points3D:positions"].to_pylist())[:, 0, :]
    truth = np.array(tables["truth"]["/world/truth/foot:Points3D:positions"].to_pylist())[:, 0, :]
    stance = _column(tables["stance"], "/plots/stance/foot:Scalars:scalars")
    clearance = _column(tables["clearance"], "/plots/clearance/foot:Scalars:scalars")
    sigma = _column(tables["sigma"], "/plots/pos_sigma/foot:Scalars:scalars")
    assert set(np.unique(stance)) == {0.0, 1.0}
    assert 0.25 < stance.mean() < 0.75  # stance phases and swings both present
    np.testing.assert_allclose(clearance, track[:, 2], atol=1e-5)
    assert 0.05 < clearance.max() < 0.3  # the foot lifts by a realistic amount
    assert np.all(np.isfinite(sigma)) and sigma[-1] > sigma[0]
    # the estimated track follows the ground truth throughout (same time line, same samples)
    horizontal = np.linalg.norm(track[:, :2] - truth[:, :2], axis=1)
    assert horizontal.max() < 0.5


def test_recording_holds_the_step_smoothed_track(demo_rrd: tuple[Path, str]) -> None:
    """With ``--step-smoothing``, each step's samples smoothed once it has ended
    (``footnav.pipeline.smoothing.stepwise``), logged at their own times: all but the last open step. (Whether
    smoothing helps is measured on real feet, ``tests/test_accuracy.py``: the emulated walk's few
    millimetres are mostly its heading's, which no smoother changes; measured 6.82 mm RMS against
    6.76 causal.)"""
    path, _ = demo_rrd
    store = RrdReader(path).stream().collect()

    def table(entity: str) -> pa.Table:
        return store.reader(index="imu_time", contents=[entity]).to_arrow_table()

    smoothed, track, truth = (table(e) for e in ("/world/foot/smoothed", "/world/foot/track", "/world/truth/foot"))
    clearance = table("/plots/clearance/foot/smoothed")
    n = smoothed.num_rows  # every 10th sample (footnav.views.logger.SMOOTHED_EVERY)
    assert (N_SAMPLES - 2_000) // 10 < n < N_SAMPLES // 10 and clearance.num_rows == n  # the walk ends standing
    t_s = pc.cast(smoothed["imu_time"], pa.int64()).to_numpy()
    assert np.array_equal(t_s, pc.cast(track["imu_time"], pa.int64()).to_numpy()[: 10 * n : 10])

    def positions(tbl: pa.Table, entity: str, step: int = 1) -> np.ndarray:
        return np.array(tbl[f"{entity}:Points3D:positions"].to_pylist())[: step * n : step, 0, :]

    pos_s = positions(smoothed, "/world/foot/smoothed")
    pos_c = positions(track, "/world/foot/track", 10)
    ref = positions(truth, "/world/truth/foot", 10)
    z = _column(clearance, "/plots/clearance/foot/smoothed:Scalars:scalars")
    np.testing.assert_allclose(z, pos_s[:, 2], atol=1e-5)  # the start floor: no level change on the flat

    def rms(p: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((p - ref) ** 2, axis=1))))

    assert rms(pos_s) < 1.05 * rms(pos_c) < 0.01
    assert 0 < float(np.abs(pos_s - pos_c).max()) < 0.01  # a smoothed track, close to the causal one


def test_realtime_pace_and_interrupt(tmp_path: Path) -> None:
    """Real-time pacing works and Ctrl-C (SIGINT) leaves a complete, readable recording."""
    import signal
    import time

    path = tmp_path / "cut.rrd"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "footnav.app",
            "demo",
            "--duration",
            "30",
            "--save",
            str(path),
            "--sessions",
            str(tmp_path),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    # wait until the capture shows the stream flowing (start-up time varies with machine load),
    # then let a few seconds of real-time walking happen before Ctrl-C
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and proc.poll() is None:
        if sum(f.stat().st_size for f in tmp_path.rglob("*.mcap")) > 50_000:
            break
        time.sleep(0.2)
    started = time.monotonic()
    time.sleep(3)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err  # the shell's code for Ctrl-C
    assert "Traceback" not in err and "interrupted" in err, err
    # the summary is of the walk up to where it stopped, not of the whole planned walk (about 35 m)
    assert "(ground truth, up to the last sample navigated)" in out, out
    walked = float(re.search(r"distance walked:\s+([\d.]+) m", out)[1])  # type: ignore[index]
    assert walked < 20.0
    if walked > 1.0:
        assert float(re.search(r"= ([\d.]+) % of distance", out)[1]) < 5.0  # type: ignore[index]
    store = RrdReader(path).stream().collect()
    n = store.reader(index="imu_time", contents=["/plots/stance/foot"]).to_arrow_table().num_rows
    walked_s = time.monotonic() - started + 5  # generous: data flowing before `started`
    assert 1000 < n < min(30_000, 1000 * walked_s)  # real time: only part of the walk had happened
    assert RrdReader(path).store() is not None  # footer written: the file was closed properly
