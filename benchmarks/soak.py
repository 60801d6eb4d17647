"""Soak: two feet at 1 kHz through ``footnav live`` for a long walk, accelerated; memory, capture, gaps.

``python -m benchmarks.soak --minutes 60`` runs, and prints as one table:

- an emulator child (:class:`footnav.device.emulator.serving.pty.PtyShoeServer` per foot, the demo's walk and
  sensor errors, optionally with wire faults) serving as fast as footnav reads (``--pace max``, the
  default: the firmware then waits for the host, so an hour takes minutes) or in real time;
- a footnav child running exactly ``footnav live --left PTY --right PTY --no-viewer --save soak.rrd``
  with its capture on, whose resident memory (``VmRSS`` from ``/proc``) is sampled every
  ``--rss-every`` seconds; it is stopped with SIGINT (as Ctrl-C) once both emulated units have sent
  their last byte and the capture has caught up.

Then it checks, per foot: the capture's device -> host bytes equal the emulator's sent bytes (SHA-256
of each; the emulator keeps the hash of every prefix within its last few kB, because a unit may still
answer footnav's last command after footnav closed the port: those unread bytes must be whole command
ACKs, and are reported), and every data packet is accounted for (the unit driver's framer and counter tracker over
the captured bytes: packets received = the emulator's packets less those the fault injector dropped
or corrupted, and those are counted lost); and reports peak RSS and its slope over the run's second half (flat means the
slope's change over the run is small against the peak). Nothing is asserted on timings; the figures
go in the README. ``tests/test_soak.py`` runs a short soak with the same code.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from footnav.device.files.capture import CaptureSummary

ROOT = Path(__file__).resolve().parents[1]
FEET = ("left", "right")
STOPPED_CODES = (0, 130)
"""footnav's exit codes for a session stopped by SIGINT: 130, the shell's code for Ctrl-C (0 before issue 28)."""


def _serve(seconds: float, pace: float, drop_rate: float, bit_error_rate: float) -> int:
    """Serve two emulated shoes; print their ports, then (once both finished) their totals."""
    from footnav.app.commands.demo import DemoOptions, demo_truth
    from footnav.device.emulator.serving.faults import WireFaults
    from footnav.device.emulator.serving.pty import PtyShoeServer

    opts = DemoOptions(duration_s=seconds, feet=2)
    faults = WireFaults(drop_rate=drop_rate, bit_error_rate=bit_error_rate)
    servers = []
    for k in range(2):
        truth, acc, gyr = demo_truth(opts, k)
        servers.append(PtyShoeServer(truth.t_s, acc, gyr, speed=pace, record=False, faults=faults, seed=k))
        del truth, acc, gyr
    for s in servers:
        s.start()
    print(json.dumps({"ports": [s.port for s in servers]}), flush=True)
    while not all(s.finished.is_set() for s in servers):
        time.sleep(0.2)
    print(json.dumps({"finished": True}), flush=True)
    # footnav has stopped the units and exited; the line holds the bytes its capture holds per unit
    captured = [int(x) for x in sys.stdin.readline().split()[1:]]
    for s in servers:
        s.stop()
    prefixes = [s.sent_prefix(n) for s, n in zip(servers, captured, strict=True)]
    report = [
        {
            "prefix_sha256": None if p is None else p[0],
            "unread": None if p is None else p[1].hex(),
            "bytes": s.bytes_written,
            "packets_in": s.fault_log.packets_in or s.packets_sent,
            "dropped": len(s.fault_log.dropped),
            "corrupted": len(s.fault_log.corrupted),
        }
        for s, p in zip(servers, prefixes, strict=True)
    ]
    print(json.dumps({"report": report}), flush=True)
    return 0


def _rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


@dataclass
class SoakResult:
    minutes: float
    wall_s: float
    rss_t_s: np.ndarray
    rss_mb: np.ndarray
    feet: dict[str, dict[str, Any]] = field(default_factory=dict)
    footnav_code: int = 0
    rrd_mb: float = math.nan
    capture_mb: float = math.nan

    @property
    def peak_mb(self) -> float:
        return float(np.nanmax(self.rss_mb)) if self.rss_mb.size else math.nan

    @property
    def slope_mb_per_h(self) -> float:
        """Least-squares slope of RSS over the run's second half, MB per hour of wall time."""
        half = self.rss_t_s >= self.rss_t_s[-1] / 2 if self.rss_t_s.size else np.zeros(0, bool)
        if np.count_nonzero(half) < 3:
            return math.nan
        return float(np.polyfit(self.rss_t_s[half], self.rss_mb[half], 1)[0] * 3600.0)

    @property
    def growth_mb(self) -> float:
        """RSS at the end minus RSS at the start of the second half (median of the first/last 5 samples)."""
        if self.rss_t_s.size < 10:
            return math.nan
        half = np.flatnonzero(self.rss_t_s >= self.rss_t_s[-1] / 2)
        if len(half) < 10:
            return math.nan
        return float(np.median(self.rss_mb[half[-5:]]) - np.median(self.rss_mb[half[:5]]))

    @property
    def ok(self) -> bool:
        captured = all(f["capture_equals_sent"] and f["accounted"] for f in self.feet.values())
        return self.footnav_code in STOPPED_CODES and captured


def _only_acks(data: bytes) -> bool:
    """True if ``data`` is nothing but whole command ACK frames (``A0 cmd chk_hi chk_lo``)."""
    from footnav.device.protocol.framer import DeviceAck, Framer

    framer = Framer()
    frames = framer.feed(data)
    return framer.buffered == 0 and framer.stats.bytes_skipped == 0 and all(isinstance(f, DeviceAck) for f in frames)


def _account(capture: Path, summary: CaptureSummary, emulator: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per foot: capture bytes vs the emulator's, and packets received + lost vs packets sent."""
    from footnav.device.files.capture import CaptureMessage, iter_capture
    from footnav.device.protocol.framer import DataPacket, Framer
    from footnav.device.protocol.imu import CounterTracker

    out: dict[str, dict[str, Any]] = {}
    for foot, emu in zip(FEET, emulator, strict=True):
        framer, tracker = Framer(), CounterTracker()
        received = 0
        for item in iter_capture(capture):
            if not isinstance(item, CaptureMessage) or item.foot != foot or item.direction != "rx":
                continue
            numbers = [f.number for f in framer.feed(item.data) if isinstance(f, DataPacket)]
            if numbers:
                _, dup = tracker.update(np.asarray(numbers))
                received += int(np.count_nonzero(~dup))
        faults = emu["dropped"] + emu["corrupted"]
        unread = bytes.fromhex(emu["unread"]) if emu["unread"] is not None else None
        out[foot] = {
            # every byte the unit sent is in the capture, in order, but for command ACKs the unit
            # wrote after footnav had closed the port (answers to its last commands)
            "capture_equals_sent": summary.rx_sha256.get(foot) == emu["prefix_sha256"]
            and unread is not None
            and _only_acks(unread),
            "unread_after_close": len(unread) if unread is not None else -1,
            "bytes": summary.rx_bytes.get(foot, 0),
            "sent_bytes": emu["bytes"],
            "received": received,
            "lost": tracker.lost,
            "emulator_packets": emu["packets_in"],
            "dropped_or_corrupted": faults,
            # every packet the emulator sent arrived once, unless the injector dropped or broke it;
            # those are counted lost (all but any at the very end, which no receiver can see)
            "accounted": received + faults == emu["packets_in"] and tracker.lost <= faults,
        }
    return out


def _readline(stream: IO[str], timeout_s: float) -> str:
    result: list[str] = []
    reader = threading.Thread(target=lambda: result.append(stream.readline()), daemon=True)
    reader.start()
    reader.join(timeout_s)
    if not result or not result[0]:
        raise RuntimeError(f"no answer from the emulator child within {timeout_s:.0f} s")
    return result[0]


def run_soak(
    minutes: float,
    work: Path,
    *,
    pace: float = math.inf,
    rss_every_s: float = 1.0,
    drop_rate: float = 0.0,
    bit_error_rate: float = 0.0,
) -> SoakResult:
    """Run the soak (see the module docstring) in ``work``; returns what it measured."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        # started in the background of a non-interactive shell: footnav's child would inherit SIGINT
        # ignored and never see the stop (a caught signal is reset to its default across exec)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("DISPLAY", None)
    env.pop("WAYLAND_DISPLAY", None)
    from footnav.device.files.capture import summarize_capture

    emu = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.soak", "_serve", "--seconds", str(minutes * 60.0), "--pace", str(pace),
         "--drop-rate", str(drop_rate), "--bit-error-rate", str(bit_error_rate)],
        cwd=ROOT, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    sessions, rrd = work / "sessions", work / "soak.rrd"
    try:
        assert emu.stdout is not None and emu.stdin is not None
        ports = json.loads(_readline(emu.stdout, 60.0 + minutes * 10.0))["ports"]
        t0 = time.monotonic()
        with open(work / "footnav.stderr", "w") as err:
            live = subprocess.Popen(
                [sys.executable, "-m", "footnav.app", "live", "--left", ports[0], "--right", ports[1], "--no-viewer",
                 "--save", str(rrd), "--sessions", str(sessions)],
                cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=err,
            )  # fmt: skip
            finished: list[str] = []
            waiter = threading.Thread(target=lambda: finished.append(emu.stdout.readline()), daemon=True)  # type: ignore[union-attr]
            waiter.start()
            times, rss = [], []
            while live.poll() is None and not finished:
                times.append(time.monotonic() - t0)
                rss.append(_rss_mb(live.pid))
                waiter.join(rss_every_s)
            time.sleep(3.0)  # the last reads reach the capture
            live.send_signal(signal.SIGINT)
            code = live.wait(120)
        wall = time.monotonic() - t0
        captures = sorted(sessions.glob("*.mcap"))
        rx = summarize_capture(captures[-1], full=True) if captures else None
        lengths = [rx.rx_bytes.get(foot, 0) if rx is not None else 0 for foot in FEET]
        emu.stdin.write("stop " + " ".join(map(str, lengths)) + "\n")
        emu.stdin.flush()
        emulator = json.loads(_readline(emu.stdout, 60.0))["report"]
        emu.wait(60)
    finally:
        for proc in (emu,):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    result = SoakResult(minutes, wall, np.asarray(times), np.asarray(rss), footnav_code=code)
    np.savetxt(work / "rss.csv", np.column_stack([times, rss]), delimiter=",", header="wall_s,rss_mb", fmt="%.2f")
    if not finished or not finished[0]:
        raise RuntimeError(f"footnav stopped (code {code}) before the emulator finished; see {work}/footnav.stderr")
    if not captures or rx is None:
        raise RuntimeError(f"footnav wrote no capture; see {work}/footnav.stderr")
    result.feet = _account(captures[-1], rx, emulator)
    result.rrd_mb = rrd.stat().st_size / 1e6 if rrd.exists() else math.nan
    result.capture_mb = captures[-1].stat().st_size / 1e6
    return result


def report(r: SoakResult) -> None:
    print(f"soak: two feet at 1 kHz, {r.minutes:g} min of walk, {r.wall_s:.0f} s wall, footnav exit {r.footnav_code}")
    print(
        f"{'':<8}{'capture = sent':>16}{'bytes':>14}{'unread ACKs':>12}{'received':>11}{'lost':>7}{'sent':>11}"
        f"{'faults':>8}"
    )
    for foot, f in r.feet.items():
        print(
            f"{foot:<8}{'yes' if f['capture_equals_sent'] else 'NO':>16}{f['bytes']:>14}{f['unread_after_close']:>12}"
            f"{f['received']:>11}{f['lost']:>7}{f['emulator_packets']:>11}{f['dropped_or_corrupted']:>8}"
        )
    print(
        f"peak RSS {r.peak_mb:.0f} MB (target <= 400); second-half slope {r.slope_mb_per_h:+.1f} MB/h, "
        f"growth {r.growth_mb:+.1f} MB; .rrd {r.rrd_mb:.0f} MB, capture {r.capture_mb:.0f} MB"
    )
    print("every byte captured and every packet accounted for" if r.ok else "FAILED: see the table")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.soak", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="cmd")
    serve = sub.add_parser("_serve")
    serve.add_argument("--seconds", type=float, required=True)
    serve.add_argument("--pace", type=float, default=math.inf)
    serve.add_argument("--drop-rate", type=float, default=0.0)
    serve.add_argument("--bit-error-rate", type=float, default=0.0)
    parser.add_argument("--minutes", type=float, default=60.0, help="walk length (default 60)")
    parser.add_argument("--pace", default="max", help="emulator pace: max (default) or a factor, 1 = real time")
    parser.add_argument("--drop-rate", type=float, default=0.0, help="wire fault: dropped packets (fraction)")
    parser.add_argument("--bit-error-rate", type=float, default=0.0, help="wire fault: bit error rate")
    parser.add_argument("--rss-every", type=float, default=1.0, metavar="S")
    parser.add_argument("--work", type=Path, help="keep the files here (default: a temporary folder)")
    args = parser.parse_args(argv)
    if args.cmd == "_serve":
        return _serve(args.seconds, args.pace, args.drop_rate, args.bit_error_rate)
    pace = math.inf if args.pace == "max" else float(args.pace)
    with tempfile.TemporaryDirectory(prefix="footnav-soak-") as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        r = run_soak(
            args.minutes, work, pace=pace, rss_every_s=args.rss_every, drop_rate=args.drop_rate,
            bit_error_rate=args.bit_error_rate,
        )  # fmt: skip
    report(r)
    return 0 if r.ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
