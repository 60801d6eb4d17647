"""``footnav live`` through link faults, end to end: the real command in a subprocess against the emulated
unit on a pty behind a stable symlink (as udev's /dev/serial/by-id links are), unplugged and replugged
mid-session. No mocks."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pytest
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.serving.pty import DEFAULT_TICK0, PtyShoeServer
from footnav.device.files.capture import iter_capture
from footnav.device.protocol import commands as protocol
from footnav.device.protocol.framer import DataPacket, Framer
from rerun.chunk import RrdReader
from rerun.error_utils import RerunWarning


def plug(path: Path, server: PtyShoeServer) -> None:
    """Point the stable port path at ``server``'s pty, atomically."""
    tmp = path.with_name(path.name + ".new")
    os.symlink(server.port, tmp)
    os.replace(tmp, path)


def wait_for(condition: Callable[[], bool], timeout_s: float, what: str, proc: subprocess.Popen[str]) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if proc.poll() is not None:
            raise AssertionError(f"footnav exited early ({proc.returncode}) while waiting for {what}")
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.05)


def test_live_session_survives_unplug_and_replug(tmp_path: Path) -> None:
    walk = simulate_walk("rectangle", 20.0, seed=1)  # 3 s standing, then walking
    t, acc, gyr = walk.t_s, walk.acc_b_mps2, walk.gyr_b_radps
    lost_while_unplugged = 500
    port = tmp_path / "ttyFOOT"
    first = PtyShoeServer(t, acc, gyr, speed=2.0, record=False)
    first.start()
    plug(port, first)
    servers = [first]
    rrd = tmp_path / "live.rrd"
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "footnav.app", "live", "--port", str(port), "--no-viewer", "--save", str(rrd),
         "--sessions", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    try:
        wait_for(lambda: first.packets_sent >= 4000, 30, "4 s of streaming before the unplug", proc)
        first.unplug()
        port.unlink()  # the device node is gone while unplugged
        time.sleep(0.7)
        # A battery-powered unit keeps numbering while its cable is out: it resumes further on.
        k = first.packets_sent + lost_while_unplugged
        second = PtyShoeServer(
            t[k:], acc[k:], gyr[k:], speed=2.0, first_packet_number=k + 1, tick0=DEFAULT_TICK0 + k * 64_000,
            record=False,
        )  # fmt: skip
        second.start()
        servers.append(second)
        plug(port, second)
        wait_for(lambda: second.packets_sent >= 3000, 20, "3 s of streaming after the replug", proc)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        for server in servers:
            server.stop()
    assert proc.returncode == 130, err  # stopped by Ctrl-C (SIGINT)
    assert "Traceback" not in err

    # The gap was reported on the terminal as it happened, and is counted in the status line.
    assert re.search(r"footnav: the unit on .*ttyFOOT was disconnected .*; reconnecting", err), err
    assert re.search(r"footnav: reconnected to .*ttyFOOT after \d+ attempts", err), err
    assert re.search(r"footnav: data from .*ttyFOOT again after [\d.]+ s, (\d+) packets missing", err), err
    status = [line for line in err.splitlines() if line.startswith("t ")]
    assert status and "reconnects 1" in status[-1], err
    m = re.search(r"samples received: (\d+) \(lost packets: (\d+)\); link: 1 reconnects, 0 stalls, 1 gaps "
                  r"\(([\d.]+) s without data, (\d+) packets missing\)", out)  # fmt: skip
    assert m, out
    received, lost, downtime, missing = int(m[1]), int(m[2]), float(m[3]), int(m[4])
    assert lost == missing >= lost_while_unplugged
    assert 0.7 < downtime < 5
    assert received >= 4000 + 3000 - 200
    # and the navigator's side of it: the samples after the gap come one long interval later
    assert re.search(r"packets missing\); 1 gaps in the stream", out), out

    # The capture holds both sides of the gap, the re-sent start command and the gap as events.
    (capture,) = tmp_path.glob("live-*.mcap")
    framer = Framer()
    numbers: list[int] = []
    tx = b""
    events: list[dict[str, object]] = []
    for item in iter_capture(capture):
        if getattr(item, "foot", None) != "foot":
            continue
        if item.direction == "rx":  # type: ignore[union-attr]
            numbers += [f.number for f in framer.feed(item.data) if isinstance(f, DataPacket)]  # type: ignore[union-attr]
        elif item.direction == "tx":  # type: ignore[union-attr]
            tx += item.data  # type: ignore[union-attr]
        else:
            events.append(json.loads(item.data))  # type: ignore[union-attr]
    jumps = np.flatnonzero(np.diff(numbers) > 1)
    assert len(jumps) == 1  # one gap; numbering continuous on either side of it
    before, after = numbers[: jumps[0] + 1], numbers[jumps[0] + 1 :]
    assert before[0] == 1 and len(before) >= 4000 - 100
    assert after[0] - before[-1] - 1 == missing and len(after) >= 3000 - 100
    assert tx.count(protocol.normal_imu_command(0)) == 2  # the driver's start, then the link's resume
    link_events = [e for e in events if e["event"] == "link"]
    assert [e["kind"] for e in link_events] == ["disconnected", "reconnected", "resumed"]
    assert link_events[-1]["packets_missing"] == missing
    assert events[-1]["event"] == "end" and events[-1]["samples"] == received

    # The recording: the gap as text events, the reconnect in the link-health plot, every sample navigated.
    with pytest.warns(RerunWarning, match="no footer"):  # live recordings keep no footer index (flat memory)
        store = RrdReader(rrd).stream().collect()
        # every event row, from the chunks: the disconnect and the reconnect come before the next
        # sample, so they can share one time stamp, and a query indexed by time keeps one row per time
        text = [
            s
            for chunk in RrdReader(rrd).stream()
            if chunk.entity_path == "/events" and not chunk.is_static
            for row in chunk.to_record_batch().column("TextLog:text").to_pylist()
            for s in row
        ]
    assert any("was disconnected" in s for s in text) and any("again after" in s for s in text), text
    errors = store.reader(index="imu_time", contents=["/plots/link_errors/foot"]).to_arrow_table()
    pairs = np.asarray(pc.list_flatten(errors["/plots/link_errors/foot:Scalars:scalars"])).reshape(-1, 2)
    assert pairs[0].tolist() == [0, 0] and pairs[-1].tolist() == [missing, 1]  # lost packets, reconnects
    track = store.reader(index="imu_time", contents=["/world/foot/track"]).to_arrow_table()
    assert track.num_rows > received - 1000  # navigated across the gap (the first 0.5 s aligns)
