"""End-to-end benchmarks: latency, CPU share, replay time, ``.rrd`` size, peak memory.

``python -m benchmarks.e2e`` runs, and prints as one table:

1. **live, one foot** and **live, two feet** at 1 kHz in real time, and two feet without any Rerun
   output (the baseline for the logging's share of CPU and latency). The emulated shoes
   (:class:`footnav.device.emulator.serving.pty.PtyShoeServer`, the demo's walk and sensor errors) run in a
   child process of their own (``_serve``), so their threads take none of the measured CPU; footnav
   runs in another child (``_live``) exactly as ``footnav live --left PTY --right PTY --no-viewer
   --save FILE.rrd`` does (``footnav.app.commands.live.live_session``, capture on, Rerun logging to a file), with one
   extra sink per foot (``LiveOptions.collect``) appended after the Rerun sink that notes
   ``time.monotonic_ns()`` when each batch has been handed to the logger. The emulator notes the
   same clock (system-wide ``CLOCK_MONOTONIC``) after each ``os.write`` to the pty, and the packets
   each write completed. Latency of a sample = hand-off time - send time of its packet; it is split
   into send -> read (pty and driver) and read -> hand-off (decode, estimator, sinks) with the batches'
   ``host_ns``. The samples held back until the initial alignment (the navigator's first batch) are
   counted apart. CPU share = footnav process CPU time (all its threads: asyncio loop, Rerun logger,
   Rerun's own) / wall time, over the steady part of the run (from 2 s after the first estimates to
   the last sample); the whole-process figure (start-up, numba cache load and shutdown included) is
   given beside it.
2. **replay**: a two-feet capture made by ``footnav demo --feet 2 --pace max`` (``--replay-minutes``
   of walk, default 60), then ``footnav replay CAPTURE --speed max --save out.rrd --no-viewer``
   timed by the wall clock, with its CPU time and peak RSS from ``wait4``.

With ``--step-smoothing`` both run with step smoothing (``footnav.pipeline.smoothing.stepwise``: the live
sessions' configuration, and the demo that makes the capture, whose replay then follows it).

Peak RSS is ``ru_maxrss`` of the footnav process (the ``_live`` child, or ``footnav replay``).
Nothing here asserts a timing; target figures from issue 9 are printed beside the measured ones.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import selectors
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

ROOT = Path(__file__).resolve().parents[1]
RATE_HZ = 1000.0
FEET = {1: ("foot",), 2: ("left", "right")}
WARMUP_S = 2.0
"""The CPU window starts this long after the first estimates of every foot."""


# --------------------------------------------------------------------------------- emulator child


def _serve(feet: int, seconds: float, out: Path) -> int:
    """Serve ``feet`` emulated shoes in real time; print their ports; on a line on stdin (or EOF),
    stop and save every write's time and bytes to ``out`` (npz)."""
    from footnav.app.commands.demo import DemoOptions, demo_truth
    from footnav.device.emulator.serving.pty import PtyShoeServer

    class TimedPtyServer(PtyShoeServer):
        """Notes ``time.monotonic_ns()`` after each write to the pty, and the bytes written so far."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **{**kwargs, "record": True})
            self.writes: list[tuple[int, int]] = []

        def _write_some(self) -> None:
            before = self.bytes_written
            super()._write_some()
            if self.bytes_written != before:
                self.writes.append((time.monotonic_ns(), self.bytes_written))

    opts = DemoOptions(duration_s=seconds, feet=feet)
    truths = [demo_truth(opts, k) for k in range(feet)]
    servers = [TimedPtyServer(t.t_s, acc, gyr, speed=1.0) for t, acc, gyr in truths]
    for s in servers:
        s.start()
    print(json.dumps({"ports": [s.port for s in servers], "samples": int(truths[0][0].t_s.size)}), flush=True)
    sys.stdin.readline()
    arrays: dict[str, Any] = {}
    for k, s in enumerate(servers):
        s.stop()
        w = np.array(s.writes, dtype=np.int64).reshape(-1, 2)
        arrays[f"write_ns_{k}"] = w[:, 0]
        arrays[f"write_end_{k}"] = w[:, 1]
        arrays[f"sent_{k}"] = np.frombuffer(s.sent_bytes, dtype=np.uint8)
    np.savez(out, **arrays)
    return 0


def packet_send_ns(write_ns: NDArray[np.int64], write_end: NDArray[np.int64], sent: bytes) -> NDArray[np.int64]:
    """Send time of every data packet, in stream order: the time of the write that completed it."""
    from footnav.device.protocol.framer import DataPacket, Framer

    framer = Framer()
    out: list[int] = []
    start = 0
    for t, end in zip(write_ns.tolist(), write_end.tolist(), strict=True):
        out.extend(t for f in framer.feed(sent[start:end]) if isinstance(f, DataPacket))
        start = end
    return np.array(out, dtype=np.int64)


# ------------------------------------------------------------------------------------ footnav child


@dataclass
class _Collected:
    t_s: list[NDArray[np.float64]] = field(default_factory=list)
    host_ns: list[NDArray[np.int64]] = field(default_factory=list)
    handoff_ns: list[int] = field(default_factory=list)
    samples: int = 0


def _live(ports: list[str], samples: int, save: Path | None, sessions: Path, out: Path, step_smoothing: bool) -> int:
    """``footnav live`` on ``ports`` with a timing sink per foot; stop (as Ctrl-C does) once every
    foot has handed ``samples`` samples to its sinks; save what the sinks saw to ``out`` (npz)."""
    from footnav.app.commands.live import LiveOptions, live_session
    from footnav.app.config import defaults
    from footnav.pipeline.nav_types import NavBatch

    wall0, cpu0 = time.monotonic(), time.process_time()
    feet = FEET[len(ports)]
    got = {f: _Collected() for f in feet}
    window: dict[str, float] = {}
    done = asyncio.Event()

    def collect(foot: str) -> Any:
        c = got[foot]

        def sink(nav: NavBatch) -> None:
            now = time.monotonic_ns()
            c.t_s.append(nav.t_s.copy())
            c.host_ns.append(nav.host_ns.copy())
            c.handoff_ns.append(now)
            c.samples += len(nav)
            if "start_wall" not in window and all(g.samples for g in got.values()):
                window["first"] = time.monotonic()
                window["start_wall"] = window["first"] + WARMUP_S
            if "start_cpu" not in window and "start_wall" in window and time.monotonic() >= window["start_wall"]:
                window["start_wall"], window["start_cpu"] = time.monotonic(), time.process_time()
            if all(g.samples >= samples for g in got.values()) and not done.is_set():
                window["end_wall"], window["end_cpu"] = time.monotonic(), time.process_time()
                done.set()

        return sink

    cfg = defaults()
    if step_smoothing:
        cfg.set("filter.step_smoothing", True, "benchmark --step-smoothing")
    cfg.set("session.sessions_dir", str(sessions), "benchmark")
    opts = LiveOptions(
        ports=dict(zip(feet, ports, strict=True)), config=cfg, save=save, viewer=False, capture=True, collect=collect
    )

    async def main() -> None:
        task = asyncio.create_task(live_session(opts))
        waiter = asyncio.create_task(done.wait())
        await asyncio.wait({task, waiter}, timeout=samples / RATE_HZ + 60.0, return_when=asyncio.FIRST_COMPLETED)
        waiter.cancel()
        if not task.done():
            task.cancel()  # what Ctrl-C does: stop the units, close capture and recording
        with contextlib.suppress(asyncio.CancelledError):
            await task

    asyncio.run(main())
    arrays: dict[str, Any] = {}
    for k, f in enumerate(feet):
        c = got[f]
        sizes = np.array([len(t) for t in c.t_s], dtype=np.int64)
        arrays[f"t_s_{k}"] = np.concatenate(c.t_s) if c.t_s else np.zeros(0)
        arrays[f"host_ns_{k}"] = np.concatenate(c.host_ns) if c.host_ns else np.zeros(0, np.int64)
        arrays[f"handoff_ns_{k}"] = np.repeat(np.array(c.handoff_ns, dtype=np.int64), sizes)
        arrays[f"first_batch_{k}"] = np.array(sizes[0] if sizes.size else 0)
    wall1, cpu1 = time.monotonic(), time.process_time()
    info = {
        "window_wall_s": window.get("end_wall", np.nan) - window.get("start_wall", np.nan),
        "window_cpu_s": window.get("end_cpu", np.nan) - window.get("start_cpu", np.nan),
        "main_wall_s": wall1 - wall0,
        "main_cpu_s": cpu1 - cpu0,
        "complete": done.is_set(),
    }
    np.savez(out, info=np.array(json.dumps(info)), **arrays)
    return 0


# ----------------------------------------------------------------------------------- orchestration


@dataclass
class ChildRun:
    wall_s: float
    cpu_s: float
    maxrss_mb: float
    code: int


def _wait(proc: subprocess.Popen[Any], t0: float) -> ChildRun:
    _, status, ru = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return ChildRun(time.perf_counter() - t0, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0, proc.returncode)


def _readline(stream: IO[str], timeout_s: float) -> str:
    sel = selectors.DefaultSelector()
    sel.register(stream, selectors.EVENT_READ)
    if not sel.select(timeout_s):
        raise TimeoutError("the emulator did not start")
    return stream.readline()


def _pct(x: NDArray[np.float64]) -> tuple[float, float, float, float]:
    if x.size == 0:
        return (np.nan,) * 4
    p50, p95, p99 = np.percentile(x, [50, 95, 99])
    return float(p50), float(p95), float(p99), float(x.max())


@dataclass
class LiveResult:
    feet: int
    seconds: float
    total_ms: NDArray[np.float64]
    transport_ms: NDArray[np.float64]
    pipeline_ms: NDArray[np.float64]
    held: int
    held_max_ms: float
    cpu_share: float
    run: ChildRun
    info: dict[str, Any]
    rrd_mb: float
    capture_mb: float
    samples: int
    rerun: bool = True


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def live_run(feet: int, seconds: float, work: Path, *, rerun: bool = True, step_smoothing: bool = False) -> LiveResult:
    """Emulator child + footnav child, real time; latencies and CPU from their logs. ``rerun=False``:
    no Rerun output at all (the baseline for the logging's share)."""
    tag = f"live{feet}" + ("" if rerun else "-norerun")
    emu_log, live_log = work / f"{tag}-emu.npz", work / f"{tag}-live.npz"
    rrd, sessions = work / f"{tag}.rrd", work / f"{tag}-sessions"
    # a little extra walk so the emulator never runs dry before footnav has its samples
    emu = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.e2e", "_serve", "--feet", str(feet), "--seconds", str(seconds + 5.0),
         "--out", str(emu_log)],
        cwd=ROOT, env=_env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert emu.stdout is not None and emu.stdin is not None
        hello = json.loads(_readline(emu.stdout, 120.0))
        samples = round(seconds * RATE_HZ)
        t0 = time.perf_counter()
        with open(work / f"{tag}-live.stderr", "w") as err:
            live = subprocess.Popen(
                [sys.executable, "-m", "benchmarks.e2e", "_live", *hello["ports"], "--samples", str(samples),
                 *(["--step-smoothing"] if step_smoothing else []),
                 *(["--save", str(rrd)] if rerun else []), "--sessions", str(sessions), "--out", str(live_log)],
                cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=err,
            )  # fmt: skip
            run = _wait(live, t0)
        emu.stdin.write("stop\n")
        emu.stdin.flush()
        emu.wait(60)
    finally:
        if emu.poll() is None:
            emu.kill()
            emu.wait()
    if run.code != 0:
        raise RuntimeError(f"the footnav child failed (code {run.code}); see {work / f'{tag}-live.stderr'}")
    e, lv = np.load(emu_log), np.load(live_log)
    info = json.loads(str(lv["info"]))
    total, transport, pipeline = [], [], []
    held, held_max = 0, 0.0
    for k in range(feet):
        send = packet_send_ns(e[f"write_ns_{k}"], e[f"write_end_{k}"], e[f"sent_{k}"].tobytes())
        t_s, host, hand = lv[f"t_s_{k}"], lv[f"host_ns_{k}"], lv[f"handoff_ns_{k}"]
        idx = np.rint(t_s * RATE_HZ).astype(np.int64)  # streams start at the first packet sent
        if idx.size and idx.max() >= send.size:
            raise RuntimeError(f"foot {k}: sample {idx.max()} but only {send.size} packets sent")
        lat = (hand - send[idx]) / 1e6
        first = int(lv[f"first_batch_{k}"])
        held += first
        held_max = max(held_max, float(lat[:first].max()) if first else 0.0)
        total.append(lat[first:])
        transport.append((host[first:] - send[idx[first:]]) / 1e6)
        pipeline.append((hand[first:] - host[first:]) / 1e6)
    return LiveResult(
        feet=feet,
        seconds=seconds,
        total_ms=np.concatenate(total),
        transport_ms=np.concatenate(transport),
        pipeline_ms=np.concatenate(pipeline),
        held=held,
        held_max_ms=held_max,
        cpu_share=info["window_cpu_s"] / info["window_wall_s"],
        run=run,
        info=info,
        rrd_mb=rrd.stat().st_size / 1e6 if rrd.exists() else np.nan,
        capture_mb=sum(p.stat().st_size for p in sessions.glob("*.mcap")) / 1e6,
        samples=sum(int(lv[f"t_s_{k}"].size) for k in range(feet)),
        rerun=rerun,
    )


@dataclass
class ReplayResult:
    minutes: float
    generate: ChildRun
    replay: ChildRun
    capture_mb: float
    rrd_mb: float


def replay_run(minutes: float, work: Path, step_smoothing: bool = False) -> ReplayResult:
    footnav = [sys.executable, "-m", "footnav.app"]
    sessions = work / "replay-sessions"
    t0 = time.perf_counter()
    gen = subprocess.Popen(
        [*footnav, "demo", "--feet", "2", "--pace", "max", "--duration", str(minutes * 60.0), "--no-viewer",
         "--sessions", str(sessions), *(["--step-smoothing"] if step_smoothing else [])],
        cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    generate = _wait(gen, t0)
    captures = sorted(sessions.glob("*.mcap"))
    if generate.code != 0 or not captures:
        raise RuntimeError(f"footnav demo --pace max failed (code {generate.code})")
    rrd = work / "replay.rrd"
    t0 = time.perf_counter()
    rep = subprocess.Popen(
        [*footnav, "replay", str(captures[-1]), "--speed", "max", "--save", str(rrd), "--no-viewer"],
        cwd=ROOT, env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    replay = _wait(rep, t0)
    if replay.code != 0:
        raise RuntimeError(f"footnav replay failed (code {replay.code})")
    return ReplayResult(minutes, generate, replay, captures[-1].stat().st_size / 1e6, rrd.stat().st_size / 1e6)


def _row(name: str, value: str, target: str = "", note: str = "") -> None:
    print(f"  {name:50s} {value:>22s}  {target:>14s}  {note}")


def report_live(r: LiveResult, baseline: LiveResult | None = None) -> None:
    label = "one foot" if r.feet == 1 else "two feet"
    output = "Rerun to a file" if r.rerun else "NO Rerun output (baseline)"
    print(f"\n  live, {label}, 1 kHz real time, {r.seconds:g} s, {output}, capture on "
          f"({r.samples} samples, {r.held} held for alignment, counted apart)")  # fmt: skip
    for name, x, target in (
        (
            "latency, send -> handed to Rerun logger" if r.rerun else "latency, send -> handed to the sinks",
            r.total_ms,
            "p95 <= 20 ms" if r.rerun else "",
        ),
        ("  send -> host read (pty, driver)", r.transport_ms, ""),
        ("  host read -> handed over (decode, ESKF)", r.pipeline_ms, ""),
    ):
        p50, p95, p99, mx = _pct(x)
        _row(name + ", p50/p95/p99", f"{p50:.2f} / {p95:.2f} / {p99:.2f} ms", target, f"max {mx:.1f} ms")
    _row("latency of the samples held for alignment, max", f"{r.held_max_ms:.0f} ms", "", "(first batch)")
    _row(
        "CPU share, steady state (footnav process)",
        f"{100 * r.cpu_share:.1f} % of a core",
        "<= 30 %" if r.feet == 2 and r.rerun else "",
        f"{r.info['window_cpu_s']:.1f} s CPU / {r.info['window_wall_s']:.1f} s wall",
    )
    if baseline is not None:
        _row("  x the same without Rerun output", f"{r.cpu_share / baseline.cpu_share:.2f}x", "", "")
    _row(
        "CPU share, whole process (start-up, shutdown)",
        f"{100 * r.run.cpu_s / r.run.wall_s:.1f} % of a core",
        "",
        f"{r.run.cpu_s:.1f} s CPU / {r.run.wall_s:.1f} s wall",
    )
    if not r.rerun:
        _row("peak RSS (ru_maxrss)", f"{r.run.maxrss_mb:.0f} MB", "", "")
        return
    _row(".rrd size per minute of walk", f"{r.rrd_mb / (r.seconds / 60):.1f} MB/min", "", f"{r.rrd_mb:.1f} MB file")
    _row("capture (.mcap) size per minute", f"{r.capture_mb / (r.seconds / 60):.2f} MB/min", "", "")
    _row("peak RSS (ru_maxrss)", f"{r.run.maxrss_mb:.0f} MB", "<= 400 MB", "")


def report_replay(r: ReplayResult) -> None:
    per_hour = r.replay.wall_s * 60.0 / r.minutes
    print(f"\n  replay, two feet, {r.minutes:g} min capture at 1 kHz (made by footnav demo --pace max "
          f"in {r.generate.wall_s:.0f} s, {r.capture_mb:.0f} MB)")  # fmt: skip
    measured = "measured" if r.minutes == 60 else f"measured on {r.minutes:g} min"
    _row("footnav replay --speed max --save --no-viewer", f"{r.replay.wall_s:.1f} s", "", measured)
    if r.minutes != 60:
        _row("  per hour of capture (EXTRAPOLATED, linear)", f"{per_hour:.0f} s", "<= 60 s", "not measured")
    else:
        _row("  per hour of capture", f"{per_hour:.0f} s", "<= 60 s", "")
    _row("  CPU time (all threads)", f"{r.replay.cpu_s:.1f} s", "", f"{r.replay.cpu_s / r.replay.wall_s:.2f} cores")
    _row("  replay speed", f"{r.minutes * 60 / r.replay.wall_s:.0f}x real time", "", "")
    _row(".rrd size per minute of walk (replay)", f"{r.rrd_mb / r.minutes:.1f} MB/min", "", f"{r.rrd_mb:.0f} MB file")
    _row("peak RSS of footnav replay (ru_maxrss)", f"{r.replay.maxrss_mb:.0f} MB", "<= 400 MB", "")
    _row("peak RSS of footnav demo --pace max (capture)", f"{r.generate.maxrss_mb:.0f} MB", "", "holds the whole walk")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in ("_serve", "_live"):
        ap = argparse.ArgumentParser()
        ap.add_argument("cmd")
        ap.add_argument("ports", nargs="*")
        ap.add_argument("--feet", type=int, default=1)
        ap.add_argument("--seconds", type=float, default=30.0)
        ap.add_argument("--samples", type=int, default=0)
        ap.add_argument("--save", type=Path)
        ap.add_argument("--sessions", type=Path)
        ap.add_argument("--out", type=Path, required=True)
        ap.add_argument("--step-smoothing", action="store_true")
        a = ap.parse_args(argv)
        if a.cmd == "_serve":
            return _serve(a.feet, a.seconds, a.out)
        return _live(a.ports, a.samples, a.save, a.sessions, a.out, a.step_smoothing)

    ap = argparse.ArgumentParser(prog="python -m benchmarks.e2e", description=__doc__.splitlines()[0])
    ap.add_argument("--one-foot-s", type=float, default=30.0, help="live one-foot run, s (default 30; 0 skips)")
    ap.add_argument("--two-feet-s", type=float, default=60.0, help="live two-feet run, s (default 60; 0 skips)")
    ap.add_argument(
        "--baseline-s", type=float, default=30.0, help="two feet without Rerun output, s (default 30; 0 skips)"
    )
    ap.add_argument("--replay-minutes", type=float, default=60.0, help="two-feet capture to replay (60; 0 skips)")
    ap.add_argument("--keep", type=Path, help="keep the files (captures, .rrd, logs) in this folder")
    ap.add_argument(
        "--step-smoothing", action="store_true", help="live sessions and the replayed capture with step smoothing"
    )
    args = ap.parse_args(argv)

    from benchmarks.machine import machine

    print("footnav end-to-end benchmark\n")
    for key, value in machine():
        print(f"  {key:22s} {value}")
    with contextlib.ExitStack() as stack:
        if args.keep is not None:
            work = args.keep
            work.mkdir(parents=True, exist_ok=True)
        else:
            work = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="footnav-bench-")))
        print(f"\n  {'figure':50s} {'measured':>22s}  {'target (#9)':>14s}  note")
        smooth = args.step_smoothing
        if args.one_foot_s > 0:
            report_live(live_run(1, args.one_foot_s, work, step_smoothing=smooth))
        base = live_run(2, args.baseline_s, work, rerun=False, step_smoothing=smooth) if args.baseline_s > 0 else None
        if args.two_feet_s > 0:
            report_live(live_run(2, args.two_feet_s, work, step_smoothing=smooth), base)
        if base is not None:
            report_live(base)
        if args.replay_minutes > 0:
            report_replay(replay_run(args.replay_minutes, work, step_smoothing=smooth))
    print(f"\n  load average (1/5/15 min) at the end: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
