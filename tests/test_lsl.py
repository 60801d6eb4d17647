"""``--lsl``: the estimates on Lab Streaming Layer, read back by real pylsl inlets on loopback.

The demo runs its emulated shoe through the real serial path (pseudo-terminal) with ``--lsl``; the
inlets must receive every navigated sample, in order, equal to what the pipeline handed its sinks,
stamped with the unit's intervals, and the gait events of the same batches. Replays of the demo's
capture and of a recording of another tool stream the same way.

liblsl is configured for the test process through ``$LSLAPICFG`` (read at its first use): IPv6 off,
127.0.0.1 as a known peer and a session id of its own, so that no other LSL stream on the machine or
the network is seen; every resolve and pull has a timeout.
"""

from __future__ import annotations

import _thread
import asyncio
import math
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from footnav.app.cli import main
from footnav.app.commands.demo import DemoOptions, run_demo
from footnav.app.commands.export import load_other_recording, navigate_recording
from footnav.app.commands.replay import ReplayOptions, run_replay
from footnav.app.commands.replay_recording import RecordingReplayOptions, run_recording_replay
from footnav.app.config import defaults
from footnav.app.feet import BLE_FIRST_FOUND, check_lsl, lsl_identity, open_lsl_outlets, wait_lsl_consumers_async
from footnav.app.parser import build_parser
from footnav.app.session import UnitAddress
from footnav.device.files.capture import read_capture_info
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.gait.events import GaitEventTracker
from footnav.pipeline.nav_types import NavBatch, concat_batches
from footnav.views.lsl import (
    EVENT_CHANNELS,
    FRAME,
    INSTALL_HINT,
    STATE_CHANNELS,
    WAIT_SLICE_S,
    LslFoot,
    LslRequest,
    lsl_feet,
    open_lsl,
    source_id,
)
from footnav.views.strides import StrideTable

DURATION_S = 20.0
RESOLVE_S = 180.0
"""How long a stream may take to appear: at once on loopback, once the session has started (a replay of a
recording navigates it first; a cold numba cache compiles the filter first); this only bounds a hang."""
QUIET_S = 2.0
"""After the session, pull until nothing has arrived for this long, s."""
WAIT_S = 30.0
"""``--lsl-wait`` of the sessions under test: they wait for the inlets before their first sample."""


@pytest.fixture(scope="module")
def pylsl(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """pylsl, with liblsl configured for this test process alone (module docstring)."""
    cfg = tmp_path_factory.mktemp("lsl") / "lsl_api.cfg"
    cfg.write_text(
        "[ports]\nIPv6 = disable\n"
        f"[lab]\nKnownPeers = {{127.0.0.1}}\nSessionID = footnav-test-{uuid.uuid4().hex[:8]}\n"
        "[log]\nlevel = -2\n",
        encoding="utf-8",
    )
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("LSLAPICFG", str(cfg))
        import pylsl

        yield pylsl


@dataclass
class Received:
    """What one inlet pulled: samples (as given) and their time stamps, and the stream's info."""

    info: Any
    samples: list[Any] = field(default_factory=list)
    stamps: list[float] = field(default_factory=list)

    def pull(self, inlet: Any, pylsl: Any) -> int:
        try:
            chunk, stamps = inlet.pull_chunk(timeout=0.0, max_samples=100_000)
        except pylsl.util.LostError:  # not raised by a recovering inlet; counted as nothing new
            return 0
        self.samples += chunk
        self.stamps += stamps
        return len(stamps)


def stream_session(pylsl: Any, session: Callable[[], int], source_ids: list[str]) -> tuple[int, dict[str, Received]]:
    """Run ``session`` in a thread while inlets on ``source_ids`` pull everything it streams; its exit
    code and what each inlet got."""
    outcome: dict[str, Any] = {}

    def run() -> None:
        try:
            outcome["code"] = session()
        except BaseException as exc:  # re-raised in the test's thread
            outcome["error"] = exc

    worker = threading.Thread(target=run, name="lsl-session", daemon=True)
    worker.start()
    inlets: dict[str, Any] = {}
    got: dict[str, Received] = {}
    deadline = time.monotonic() + RESOLVE_S
    for sid in source_ids:
        found = pylsl.resolve_byprop("source_id", sid, 1, max(0.1, deadline - time.monotonic()))
        assert found, f"no LSL stream with source_id {sid!r} within {RESOLVE_S} s ({outcome})"
        inlet = pylsl.StreamInlet(found[0], max_buflen=360)  # recovers: never lost, its buffer never cut
        inlet.open_stream(timeout=10.0)
        inlets[sid] = inlet
        got[sid] = Received(inlet.info(timeout=10.0))
    end = time.monotonic() + 300.0
    while worker.is_alive() and time.monotonic() < end:
        if not sum(got[sid].pull(inlet, pylsl) for sid, inlet in inlets.items()):
            time.sleep(0.05)
    worker.join(timeout=1.0)
    assert not worker.is_alive(), "the session did not end"
    quiet_until = time.monotonic() + QUIET_S  # what arrives in the last moments
    while time.monotonic() < quiet_until:
        if sum(got[sid].pull(inlet, pylsl) for sid, inlet in inlets.items()):
            quiet_until = time.monotonic() + QUIET_S
        time.sleep(0.05)
    for inlet in inlets.values():
        inlet.close_stream()
    if "error" in outcome:
        raise outcome["error"]
    return int(outcome["code"]), got


def collector() -> tuple[dict[str, list[NavBatch]], Callable[[str], Callable[[NavBatch], None]]]:
    got: dict[str, list[NavBatch]] = {}

    def make(foot: str) -> Callable[[NavBatch], None]:
        return got.setdefault(foot, []).append

    return got, make


@dataclass
class DemoRun:
    nav: NavBatch
    state: Received
    events: Received
    capture: Path
    before: float
    after: float


@pytest.fixture(scope="module")
def demo_run(pylsl: Any, tmp_path_factory: pytest.TempPathFactory) -> DemoRun:
    """A 20 s demo walk through the real serial path, its estimates streamed to LSL and collected."""
    sessions = tmp_path_factory.mktemp("sessions")
    cfg = defaults()
    cfg.set("session.sessions_dir", str(sessions), "test")
    collected, make = collector()
    opts = DemoOptions(
        duration_s=DURATION_S,
        viewer=False,
        realtime=math.inf,
        config=cfg,
        collect=make,
        lsl=LslRequest(wait_s=WAIT_S),
    )
    before = pylsl.local_clock()
    code, got = stream_session(pylsl, lambda: run_demo(opts), ["footnav:emulator:foot", "footnav:emulator:events"])
    after = pylsl.local_clock()
    assert code == 0
    (capture,) = sessions.glob("*.mcap")
    return DemoRun(
        concat_batches(collected["foot"]),
        got["footnav:emulator:foot"],
        got["footnav:emulator:events"],
        capture,
        before,
        after,
    )


def assert_state_equals(received: Received, nav: NavBatch, *, repeated_times: bool = False) -> float:
    """The inlet got every sample of ``nav``, in order, equal; stamped with the unit's intervals
    (``repeated_times``: a recording whose clock repeats some time stamps). Returns the clock offset
    (LSL time - unit time), s."""
    x = np.asarray(received.samples, dtype=np.float64)
    ts = np.asarray(received.stamps, dtype=np.float64)
    assert x.shape == (len(nav), len(STATE_CHANNELS))
    np.testing.assert_array_equal(x[:, 0:3], nav.pos_n_m)
    np.testing.assert_array_equal(x[:, 3:6], nav.vel_n_mps)
    np.testing.assert_array_equal(x[:, 6:10], nav.quat_nb_wxyz)
    np.testing.assert_array_equal(x[:, 10], nav.stance.astype(np.float64))
    sigma = np.sqrt(np.diagonal(nav.pos_cov_n_m2, axis1=1, axis2=2))
    np.testing.assert_array_equal(x[:, 11:14], sigma)
    assert np.all(np.diff(ts) >= 0) if repeated_times else np.all(np.diff(ts) > 0)
    np.testing.assert_allclose(np.diff(ts), np.diff(nav.t_s), rtol=0, atol=1e-9)  # the unit's intervals
    offset = ts - nav.t_s
    assert float(np.ptp(offset)) < 1e-9  # one mapping for the whole session
    return float(offset[0])


def event_rows(received: Received) -> list[dict[str, str]]:
    labels = [label for label, _, _ in EVENT_CHANNELS]
    return [dict(zip(labels, row, strict=True)) for row in received.samples]


def toe_offs(stance: np.ndarray) -> np.ndarray:
    """Indices of the first swing sample after each stance (the still start counts as a stance)."""
    return np.flatnonzero(stance[:-1] & ~stance[1:]) + 1


def test_every_navigated_sample_arrives_in_order_with_the_units_intervals(demo_run: DemoRun) -> None:
    nav = demo_run.nav
    assert len(nav) == int(DURATION_S * 1000)  # every sample of the walk was navigated
    offset = assert_state_equals(demo_run.state, nav)
    # the first sample is stamped with the LSL time it was pushed at, during the run
    assert demo_run.before < nav.t_s[0] + offset < demo_run.after


def test_the_stream_describes_its_channels_frame_and_unit(demo_run: DemoRun, pylsl: Any) -> None:
    info = demo_run.state.info
    assert info.name() == "footnav foot navigation" and info.type() == "MoCap"
    assert info.source_id() == "footnav:emulator:foot"
    assert info.channel_count() == 14 and info.channel_format() == pylsl.cf_double64
    assert info.nominal_srate() == 1000.0
    desc = info.desc()
    ch = desc.child("channels").child("channel")
    channels = []
    for _ in range(info.channel_count()):
        channels.append((ch.child_value("label"), ch.child_value("unit"), ch.child_value("type")))
        ch = ch.next_sibling()
    assert channels == list(STATE_CHANNELS)
    assert channels[0] == ("pos_x", "m", "PositionX") and channels[3][1] == "m/s" and channels[11][1] == "m"
    assert desc.child_value("frame") == FRAME and desc.child_value("foot") == "foot"
    assert desc.child_value("unit") == "footnav emulator (mpu6500x4)"
    events = demo_run.events.info
    assert events.name() == "footnav gait events" and events.type() == "Markers"
    assert events.nominal_srate() == pylsl.IRREGULAR_RATE and events.channel_format() == pylsl.cf_string
    labels, ch = [], events.desc().child("channels").child("channel")
    for _ in range(events.channel_count()):
        labels.append(ch.child_value("label"))
        ch = ch.next_sibling()
    assert labels == [label for label, _, _ in EVENT_CHANNELS]


def test_the_event_stream_delivers_the_steps_and_strides(demo_run: DemoRun) -> None:
    nav, rows = demo_run.nav, event_rows(demo_run.events)
    offset = demo_run.state.stamps[0] - float(nav.t_s[0])
    for row, stamp in zip(rows, demo_run.events.stamps, strict=True):  # the state stream's clock mapping
        assert row["foot"] == "foot"
        assert abs(stamp - (float(row["t_unit_s"]) + offset)) < 2e-6
    t_of = {kind: np.array([float(r["t_unit_s"]) for r in rows if r["event"] == kind]) for kind in
            ("stance_start", "stance_end", "stride")}  # fmt: skip
    assert nav.step_onsets is not None and nav.step_onsets.size >= 10  # a step about every second
    np.testing.assert_allclose(t_of["stance_start"], nav.t_s[nav.step_onsets], atol=1e-6)
    np.testing.assert_allclose(t_of["stance_end"], nav.t_s[toe_offs(nav.stance)], atol=1e-6)
    starts = [r for r in rows if r["event"] == "stance_start"]
    for row, k in zip(starts, nav.step_onsets, strict=True):
        np.testing.assert_allclose([float(row[c]) for c in ("x_m", "y_m", "z_m")], nav.pos_n_m[k], atol=6e-5)
    # strides: the viewer's stride table fed the whole track at once agrees with the streamed events
    table = StrideTable(("foot",))
    table.update("foot", GaitEventTracker().annotate(nav))
    want = table.strides("foot")
    strides = [r for r in rows if r["event"] == "stride"]
    assert len(strides) == len(want) >= 8
    np.testing.assert_allclose([float(r["length_m"]) for r in strides], [s.length_m for s in want], atol=6e-5)
    np.testing.assert_allclose([float(r["duration_s"]) for r in strides], [s.duration_s for s in want], atol=6e-5)
    lengths = np.array([s.length_m for s in want])
    assert np.all((lengths > 1.0) & (lengths < 2.0))  # 1.4 m/s walking, a stride about a second


def test_a_replay_of_the_capture_streams_the_same_estimates(demo_run: DemoRun, pylsl: Any) -> None:
    (unit,) = read_capture_info(demo_run.capture).units
    sid = f"footnav:replay:{unit.port}:foot"
    collected, make = collector()
    opts = ReplayOptions(
        path=demo_run.capture, config=defaults(), viewer=False, collect=make, lsl=LslRequest(wait_s=WAIT_S)
    )
    code, got = stream_session(pylsl, lambda: run_replay(opts), [sid, f"footnav:replay:{unit.port}:events"])
    assert code == 0
    replayed = concat_batches(collected["foot"])
    np.testing.assert_array_equal(replayed.pos_n_m, demo_run.nav.pos_n_m)  # replay equals live
    assert_state_equals(got[sid], demo_run.nav)
    live_events = [r for r in event_rows(demo_run.events)]
    assert event_rows(got[f"footnav:replay:{unit.port}:events"]) == live_events


def test_a_replay_of_a_recording_streams_its_navigation(pylsl: Any, shared_data: Path) -> None:
    path = shared_data / "xio-gait-tracking" / "short_walk.csv"
    opts = RecordingReplayOptions(path=path, viewer=False, lsl=LslRequest(wait_s=WAIT_S))
    rec = load_other_recording(path, None, None)
    sid = f"footnav:replay:{rec.name}:foot"
    code, got = stream_session(pylsl, lambda: run_recording_replay(opts), [sid, f"footnav:replay:{rec.name}:events"])
    assert code == 0
    nav, _ = navigate_recording(rec, None, None, True)
    assert got[sid].info.nominal_srate() == pytest.approx(rec.rate_hz)
    assert np.count_nonzero(np.diff(nav.t_s) <= 0) > 0  # the x-io clock repeats some stamps: so does LSL
    assert_state_equals(got[sid], nav, repeated_times=True)
    rows = event_rows(got[f"footnav:replay:{rec.name}:events"])
    assert sum(r["event"] == "stride" for r in rows) >= 5


def test_without_pylsl_the_error_says_how_to_install_it(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    monkeypatch.setitem(sys.modules, "pylsl", None)  # `import pylsl` raises ImportError
    with pytest.raises(FootnavError, match=r"pip install 'footnav\[lsl\]'"):
        open_lsl([LslFoot("foot", "emulator", "test", 1000.0)])
    code = main(["demo", "--duration", "5", "--no-viewer", "--sessions", str(tmp_path), "--lsl"])
    assert code == 2
    assert INSTALL_HINT in capsys.readouterr().err
    assert not list(tmp_path.glob("*.mcap"))  # it stopped before the session started


def test_the_options_and_the_lazy_import() -> None:
    args = build_parser().parse_args(["replay", "x.mcap", "--lsl", "--lsl-wait", "2.5"])
    assert args.lsl and args.lsl_wait == 2.5
    assert main(["demo", "--lsl-wait", "3", "--no-viewer"]) == 2  # --lsl-wait without --lsl
    code = (
        "import sys, footnav.views.lsl, footnav.app.feet, footnav.app.commands.live, footnav.app.cli; "
        "print('pylsl' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=dict(os.environ))
    assert out.stdout.strip() == "False"  # pylsl loads only when --lsl is used


@pytest.mark.parametrize("text", ["inf", "Infinity", "nan", "-1"])
def test_lsl_wait_must_be_a_finite_time(text: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(["demo", "--lsl", "--lsl-wait", text])
    assert f"argument --lsl-wait: expected a finite time in seconds, >= 0, got {text!r}" in capsys.readouterr().err
    with pytest.raises(ValueError, match="finite time >= 0"):
        LslRequest(wait_s=float(text))
    args = build_parser().parse_args(["replay", "x.mcap", "--end", "inf", "--lsl-wait", "0"])
    assert args.end == math.inf and args.lsl_wait == 0.0  # --end may stay open; only the wait must end


def test_a_ctrl_c_during_the_wait_stops_it_within_a_slice_and_closes_the_outlets(
    pylsl: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    feet = [LslFoot("foot", f"test-interrupt-{uuid.uuid4().hex[:6]}", "test", 1000.0)]
    timer = threading.Timer(0.5, _thread.interrupt_main)  # Ctrl-C (SIGINT) for the main thread
    start = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        open_lsl_outlets(feet, wait_s=60.0)  # nobody consumes: it would wait the whole 60 s
    waited = time.monotonic() - start
    timer.join()
    assert 0.5 <= waited < 0.5 + 10 * WAIT_SLICE_S  # stopped a slice after the interrupt, not after 60 s
    err = capsys.readouterr().err
    assert "LSL: waiting up to 60 s" in err
    assert "LSL: samples streamed: foot 0; gait events: 0" in err  # closed by open_lsl_outlets itself


def test_the_async_wait_stops_at_once_when_cancelled(pylsl: Any) -> None:
    lsl = open_lsl([LslFoot("foot", f"test-cancel-{uuid.uuid4().hex[:6]}", "test", 1000.0)])

    async def cancel_the_wait() -> float:
        task = asyncio.create_task(wait_lsl_consumers_async(lsl, 60.0))
        await asyncio.sleep(0.3)
        start = time.monotonic()
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        return time.monotonic() - start

    try:
        assert asyncio.run(cancel_the_wait()) < WAIT_SLICE_S  # no C call or thread to wait out
        assert lsl.missing_consumers() == ["footnav foot navigation", "footnav gait events"]
    finally:
        lsl.close()
    with pytest.raises(ValueError, match="finite time >= 0"):
        lsl.wait_for_consumers(math.inf, notice=print)


def test_the_wait_ends_when_every_stream_has_a_consumer(pylsl: Any) -> None:
    ident = f"test-consumer-{uuid.uuid4().hex[:6]}"
    lsl = open_lsl([LslFoot("foot", ident, "test", 1000.0)])
    inlets = []
    try:
        for sid in (source_id(ident, "foot"), source_id(ident, "events")):
            (found,) = pylsl.resolve_byprop("source_id", sid, 1, 30.0)
            inlet = pylsl.StreamInlet(found)
            inlet.open_stream(timeout=10.0)
            inlets.append(inlet)
        notes: list[str] = []
        assert lsl.wait_for_consumers(30.0, notice=notes.append)
        assert notes == ["LSL: waiting up to 30 s for a consumer of footnav foot navigation, footnav gait events"]
    finally:
        for inlet in inlets:
            inlet.close_stream()
        lsl.close()


def test_a_ctrl_c_during_the_demos_wait_ends_the_session(pylsl: Any, tmp_path: Path) -> None:
    """The whole command in a process of its own, interrupted by a real SIGINT while it waits for consumers."""
    cmd = [sys.executable, "-m", "footnav.app.cli", "demo", "--duration", "5", "--no-viewer"]
    cmd += ["--sessions", str(tmp_path), "--lsl", "--lsl-wait", "120"]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, env=dict(os.environ), cwd=tmp_path)
    assert proc.stderr is not None
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if "LSL: waiting up to 120 s" in line:
            break
    else:
        pytest.fail(f"the demo never waited: {''.join(lines)}")
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out = proc.communicate(timeout=60)[1]  # it would run 120 s + the walk without the interrupt
    assert time.monotonic() - sent < 60
    assert proc.returncode == 130
    assert "LSL: samples streamed: foot 0; gait events: 0" in out  # the outlets were closed


def test_a_smoothed_replay_streams_the_smoothed_track(pylsl: Any, shared_data: Path) -> None:
    path = shared_data / "xio-gait-tracking" / "short_walk.csv"
    opts = RecordingReplayOptions(path=path, viewer=False, smooth="whole", lsl=LslRequest(wait_s=WAIT_S))
    rec = load_other_recording(path, None, None)
    sid = f"footnav:replay:{rec.name}:foot"
    code, got = stream_session(pylsl, lambda: run_recording_replay(opts), [sid, f"footnav:replay:{rec.name}:events"])
    assert code == 0
    smoothed, _ = navigate_recording(rec, None, "whole", True)
    causal, _ = navigate_recording(rec, None, None, True)
    assert float(np.max(np.abs(smoothed.pos_n_m - causal.pos_n_m))) > 0.01  # the two tracks differ
    assert_state_equals(got[sid], smoothed, repeated_times=True)


def test_the_lsl_identity_of_a_unit(pylsl: Any, capsys: pytest.CaptureFixture[str]) -> None:
    identity = {text: lsl_identity(UnitAddress.parse(text)) for text in ("/dev/ttyACM0", "COM3", "ble:Oblu-7", "ble:")}
    assert identity == {
        "/dev/ttyACM0": "/dev/ttyACM0",
        "COM3": "COM3",
        "ble:Oblu-7": "ble:Oblu-7",
        "ble:": BLE_FIRST_FOUND,
    }
    assert lsl_identity(UnitAddress.parse("ble")) == BLE_FIRST_FOUND
    assert lsl_identity(UnitAddress.parse("ble:AA:BB:CC:DD:EE:FF")) == "ble:AA:BB:CC:DD:EE:FF"
    assert source_id(lsl_identity(UnitAddress.parse("ble:")), "foot") == "footnav:ble:first-found:foot"
    streams = lsl_feet(
        LslRequest(), {"left": "ble:Oblu-7", "right": BLE_FIRST_FOUND}, units="u", rates={"left": 1.0, "right": 1.0}
    )
    check_lsl(streams)
    assert "ble:NAME or ble:ADDRESS" in capsys.readouterr().err  # said, not silently an id for any unit
    assert streams is not None
    check_lsl(streams[:1])
    assert capsys.readouterr().err == ""
