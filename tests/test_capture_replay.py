"""Capture files and replay: replay equals live exactly, truncated/foreign files, kill -9 mid-capture."""

from __future__ import annotations

import asyncio
import contextlib
import csv
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from footnav.app.commands.demo import DemoOptions, run_demo
from footnav.app.commands.export import run_export
from footnav.app.commands.live import LiveOptions, live_session
from footnav.app.commands.replay import FULL_SPEED_JOIN_SAMPLES, ReplayOptions, run_replay
from footnav.app.config import defaults
from footnav.device import unit as unit_module
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.serving.faults import WireFaults
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.files.capture import (
    FLUSH_PERIOD_S,
    CaptureInfo,
    CaptureWriter,
    UnitHeader,
    iter_capture,
    read_capture_info,
    summarize_capture,
)
from footnav.device.protocol.framer import Framer
from footnav.pipeline.errors import FootnavError, InputFormatError
from footnav.pipeline.nav_types import NavBatch, concat_batches
from mcap.writer import Writer

FIELDS = ("t_s", "pos_n_m", "vel_n_mps", "quat_nb_wxyz", "pos_cov_n_m2", "stance", "detector_stat",
          "detector_threshold", "clearance_m", "host_ns")  # fmt: skip


def collector() -> tuple[dict[str, list[NavBatch]], Callable[[str], Callable[[NavBatch], None]]]:
    got: dict[str, list[NavBatch]] = {}

    def make(foot: str) -> Callable[[NavBatch], None]:
        return got.setdefault(foot, []).append

    return got, make


def demo_capture(tmp: Path, *, pace: float, duration_s: float, feet: int = 1) -> tuple[Path, dict[str, NavBatch]]:
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp), "test")
    cfg.set("session.capture_flush_s", 0.1, "test: many chunks in a short capture")
    got, make = collector()
    code = run_demo(
        DemoOptions(duration_s=duration_s, viewer=False, realtime=pace, feet=feet, config=cfg, collect=make)
    )
    assert code == 0
    (path,) = tmp.glob("*.mcap")
    return path, {foot: concat_batches(b) for foot, b in got.items()}


def replay(path: Path, **kw: object) -> dict[str, NavBatch]:
    got, make = collector()
    assert run_replay(ReplayOptions(path=path, config=defaults(), viewer=False, collect=make, **kw)) == 0  # type: ignore[arg-type]
    return {foot: concat_batches(b) for foot, b in got.items()}


def assert_identical(a: NavBatch, b: NavBatch) -> None:
    assert len(a) == len(b)
    for name in FIELDS:
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        assert x.dtype == y.dtype, name
        np.testing.assert_array_equal(x, y, err_msg=name)  # bit for bit, host times included


@pytest.mark.parametrize(("pace", "duration_s"), [(math.inf, 20.0), (4.0, 8.0)])
def test_replay_equals_live_exactly(tmp_path: Path, pace: float, duration_s: float) -> None:
    path, live = demo_capture(tmp_path, pace=pace, duration_s=duration_s)
    assert len(live["foot"]) == int(duration_s * 1000)
    info = read_capture_info(path)
    assert info.session["footnav_version"] and info.session["format_version"] == "1"
    (unit,) = info.units
    assert unit.foot == "foot" and unit.transport == "pty (emulator)" and "0x40" in unit.unit
    assert unit.settings["rate_divider_log2"] == 0 and unit.settings["nav_config"]["profile"]["name"]
    assert unit.command_set and unit.calibration
    assert_identical(live["foot"], replay(path)["foot"])


def test_full_speed_replay_joins_reads_into_large_batches(tmp_path: Path) -> None:
    """Paced live, a read holds a few packets; replayed at full speed the navigator gets batches of
    about ``FULL_SPEED_JOIN_SAMPLES`` (the same estimates); replayed paced, one batch per read."""
    path, live = demo_capture(tmp_path, pace=4.0, duration_s=6.0)
    joined, make = collector()
    assert run_replay(ReplayOptions(path=path, config=defaults(), viewer=False, collect=make)) == 0
    per_read, make_paced = collector()
    assert run_replay(ReplayOptions(path=path, config=defaults(), viewer=False, collect=make_paced, speed=50.0)) == 0
    sizes = [len(b) for b in joined["foot"]]
    # the navigator holds the still start for its alignment, then passes each batch through
    assert all(n >= FULL_SPEED_JOIN_SAMPLES for n in sizes[1:-1]), sizes
    assert len(per_read["foot"]) > 5 * len(sizes)
    assert_identical(live["foot"], concat_batches(joined["foot"]))
    assert_identical(live["foot"], concat_batches(per_read["foot"]))


def test_two_feet_capture_replays_both(tmp_path: Path) -> None:
    path, live = demo_capture(tmp_path, pace=math.inf, duration_s=12.0, feet=2)
    assert read_capture_info(path).feet == ("left", "right")
    again = replay(path)
    for foot in ("left", "right"):
        assert_identical(live[foot], again[foot])
    # the window is in session seconds, exact to the sample
    part = replay(path, start_s=1.0, end_s=8.0)["left"]
    assert 1.0 <= part.t_s[0] < 1.002 and 7.998 < part.t_s[-1] <= 8.0
    # exported with --steps: a track and a steps file per foot, named by the foot
    summary = run_export(
        path, tmp_path / "t.csv", fmt=None, columns=None, profile=None, smooth=None, steps_out=tmp_path / "s.csv"
    )
    for foot in ("left", "right"):
        assert (tmp_path / f"t-{foot}.csv").exists()
        with (tmp_path / f"s-{foot}.csv").open() as f:
            rows = list(csv.DictReader(f))
        assert sum(int(r["is_step"]) for r in rows) >= 4, summary
        assert all(r["c_xx"] for r in rows)


def test_capture_holds_both_directions_and_header(tmp_path: Path) -> None:
    path = tmp_path / "c.mcap"
    with CaptureWriter(path, session={"command": "test"}) as w:
        tap = w.add_unit(UnitHeader("foot", "u", "openshoe-2015", "serial", "/dev/ttyX", {"k": 1}, {"c": 2}))
        tap("tx", 5, b"\x40\x00\x40")
        tap("rx", 7, b"\xa0\x40\x00\xe0")
        w.event("foot", "end", samples=0)
    items = list(iter_capture(path))
    assert isinstance(items[0], CaptureInfo) and items[0].session["command"] == "test"
    assert items[0].units[0].settings == {"k": 1} and items[0].units[0].calibration == {"c": 2}
    msgs = [(m.direction, m.host_ns, m.data) for m in items[1:] if not isinstance(m, CaptureInfo)]
    assert msgs[:2] == [("tx", 5, b"\x40\x00\x40"), ("rx", 7, b"\xa0\x40\x00\xe0")]
    assert msgs[2][0] == "events"


def test_truncated_capture_replays_up_to_its_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, live = demo_capture(tmp_path, pace=8.0, duration_s=15.0)  # ~19 chunks of 100 ms
    data = path.read_bytes()
    cut = tmp_path / "cut" / "cut.mcap"
    cut.parent.mkdir()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    assert summarize_capture(cut).truncated
    got = replay(cut)["foot"]
    assert 1000 < len(got) < len(live["foot"])
    assert_identical(got, NavBatch(**{f: getattr(live["foot"], f)[: len(got)] for f in FIELDS}))
    assert "ends mid-record" in capsys.readouterr().err
    broken = tmp_path / "cut" / "broken.mcap"
    flipped = bytearray(data)
    flipped[int(len(data) * 0.5)] ^= 0x10  # inside a compressed chunk: its CRC no longer matches
    broken.write_bytes(bytes(flipped))
    assert summarize_capture(broken, full=True).corrupt_at is not None
    got = replay(broken)["foot"]
    assert 1000 < len(got) < len(live["foot"])
    assert got.t_s[-1] == live["foot"].t_s[-1]  # resumed at the next intact chunk, to the end
    assert "are damaged and were skipped" in capsys.readouterr().err
    tiny = tmp_path / "cut" / "tiny.mcap"
    tiny.write_bytes(data[:20])
    with pytest.raises(InputFormatError, match=r"expected a footnav capture \(\.mcap"):
        replay(tiny)


def test_foreign_files_name_what_was_expected(tmp_path: Path) -> None:
    csv = tmp_path / "x-io.csv"
    csv.write_text("Time (s),Gyroscope X (deg/s)\n0,0\n")
    mat = tmp_path / "pyshoe.mat"
    mat.write_bytes(b"MATLAB 5.0 MAT-file" + bytes(200))
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    ros = tmp_path / "ros.mcap"
    with open(ros, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="rosbag2")
        w.finish()
    for path, needle in [(csv, "unsupported format"), (mat, "unsupported format"), (empty, "empty file"),
                         (ros, "another tool")]:  # fmt: skip
        with pytest.raises(InputFormatError, match="expected a footnav capture") as err:
            replay(path)
        assert needle in str(err.value)
    # the command line takes files that are not captures as recordings from other tools: it names
    # what those must hold
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "replay", str(csv), "--no-viewer"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "expected an x-io CSV with columns Time (s), Gyroscope X (deg/s)" in proc.stderr


def test_kill_9_leaves_a_readable_capture(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "footnav.app", "demo", "--duration", "30", "--no-viewer", "--sessions", str(tmp_path)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # wait for ~3 s of streamed data on disk
            files = list(tmp_path.glob("*.mcap"))
            if files and files[0].stat().st_size > 100_000:
                break
            time.sleep(0.2)
        time.sleep(0.5)
        size_before_kill = files[0].stat().st_size
        killed_ns = time.monotonic_ns()  # the same clock as the capture's host times
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    (path,) = files
    assert path.stat().st_size >= size_before_kill  # nothing lost after the last flush
    summary = summarize_capture(path)
    assert summary.rx_bytes["foot"] > 50_000 and summary.duration_s > 1.5
    assert summary.last_ns is not None and (killed_ns - summary.last_ns) / 1e9 < FLUSH_PERIOD_S + 0.5
    assert "end" not in [e.get("event") for e in summary.events.get("foot", [])]
    got = replay(path)["foot"]
    assert len(got) > 2000


def _file_size_limit(limit_bytes: int) -> Callable[[], None]:
    """A child's file size limit: writing past it fails with EFBIG, as a full disk fails with ENOSPC."""
    import resource

    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # an error from write(), not a killed process
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return apply


def test_full_disk_stops_the_capture_with_a_message_and_the_session_goes_on(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    command = [sys.executable, "-m", "footnav.app", "demo", "--duration", "60", "--pace", "max", "--no-viewer"]
    proc = subprocess.run(
        [*command, "--sessions", str(tmp_path)],
        check=False,
        capture_output=True,
        text=True,
        env=env,
        preexec_fn=_file_size_limit(1_000_000),  # about half of the walk's capture
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert "capture stopped: File too large" in proc.stderr and "STOPPED EARLY" in proc.stderr
    assert "samples navigated: 60000 of 60000" in proc.stdout  # the session went on to the end
    (path,) = tmp_path.glob("*.mcap")
    assert path.stat().st_size <= 1_000_000
    got = replay(path)["foot"]  # readable up to the last chunk that fitted
    assert 5000 < len(got) < 60_000


def test_a_window_mid_walk_starts_from_the_state_the_capture_had_there(tmp_path: Path) -> None:
    """Mid-walk the foot never rests the 0.5 s the alignment needs: the window is navigated from the
    capture's start and shown from its own (before: 0 samples navigated, exit 0, no reason)."""
    path, _ = demo_capture(tmp_path, pace=math.inf, duration_s=20.0)
    full = replay(path)["foot"]
    part = replay(path, start_s=8.0, end_s=12.0)["foot"]
    assert 8.0 <= part.t_s[0] < 8.002 and 11.998 < part.t_s[-1] <= 12.0
    k = int(np.searchsorted(full.t_s, part.t_s[0]))
    np.testing.assert_array_equal(part.pos_n_m, full.pos_n_m[k : k + len(part)])  # the same estimates
    with pytest.raises(FootnavError, match=r"--start 500 s is after the end of the capture \(20\.0 s of device"):
        replay(path, start_s=500.0)


WIRES = {
    # packets lost, repeated, reordered: every byte in a frame, the reads joined are framed in one pass
    "numbers": (WireFaults(drop_rate=0.003, duplicate_rate=0.003, reorder_rate=0.003), None, "split_by_read"),
    # bit errors and garbage: the reads with bytes in no frame are framed read by read
    "bytes": (WireFaults(bit_error_rate=5e-5), 40, "rewind"),
}


@pytest.mark.parametrize("wire", WIRES)
def test_a_faulty_wire_replays_exactly_with_reads_joined(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, wire: str
) -> None:
    """Faults on the wire: the full-speed replay frames its joined reads in one pass where it can (clean
    stretches decoded at once, each packet stamped with its own read's host time; the others read by read)
    and gives the live session's estimates bit for bit."""
    faults, garbage_every, path_taken = WIRES[wire]
    walk = simulate_walk("rectangle", 20.0, rate_hz=1000.0, seed=3)
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    live: list[NavBatch] = []

    async def session(server: PtyShoeServer) -> None:
        opts = LiveOptions(ports={"foot": server.port}, config=cfg, viewer=False, collect=lambda _f: live.append)
        task = asyncio.create_task(live_session(opts))
        async with asyncio.timeout(120):
            seen = -1
            while not (server.finished.is_set() and seen == sum(len(b) for b in live)) and not task.done():
                seen = sum(len(b) for b in live)
                await asyncio.sleep(0.5)
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task

    with PtyShoeServer(
        walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps, speed=4.0, faults=faults, garbage_every=garbage_every, seed=5
    ) as server:
        asyncio.run(session(server))
    (path,) = tmp_path.glob("*.mcap")
    calls: list[str] = []
    split, rewind = unit_module.split_by_read, Framer.rewind
    # spies: which way the joined reads went
    monkeypatch.setattr(unit_module, "split_by_read", lambda *a: calls.append("split_by_read") or split(*a))
    monkeypatch.setattr(Framer, "rewind", lambda *a: calls.append("rewind") or rewind(*a))
    again = replay(path)["foot"]
    live_nav = concat_batches(live)
    assert len(live_nav) > 15_000 and path_taken in calls
    assert len(again) >= len(live_nav)  # the live session was stopped; the capture holds all it read
    for name in FIELDS:
        x, y = np.asarray(getattr(live_nav, name)), np.asarray(getattr(again, name))[: len(live_nav)]
        np.testing.assert_array_equal(x, y, err_msg=name)
