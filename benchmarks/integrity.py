"""Packet integrity: corrupted packets that pass the unit's 16-bit checksum, and those that reach the samples.

``python -m benchmarks.integrity`` prints two tables:

- **pass rates**: an emulated walk at 1 kHz (``--seconds``, 60 by default) through the emulator's
  fault injector at bit error rates 1e-4, 1e-3 and 1e-2, every copy logged; the packets whose
  checksum still matches (what the sum misses), and those the unit driver (framer, sequence
  tracking, plausibility) delivered with a value that differs from the one sent, with the largest
  such error; fed to :class:`footnav.device.unit.OpenShoeUnit` in reads of about ten packets, as a
  live session reads them;
- **live accounting**: ``footnav live`` on the emulated unit on a pty (``--live`` seconds of walk, 45
  by default, at ``--speed``) with bit errors 1e-3, 5 % drops, 2 % duplicates, 2 % reordering and
  garbage bytes between packets; its capture is replayed through the same driver, and every packet
  the emulator sent is checked: delivered once, or counted lost or rejected, and each delivered sample
  against the value the emulator meant to send.

``tests/test_packet_integrity.py`` runs both, shorter, with the same code.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

BERS = (1e-4, 1e-3, 1e-2)
LIVE_FAULTS: dict[str, float] = {
    "bit_error_rate": 1e-3,
    "drop_rate": 0.05,
    "duplicate_rate": 0.02,
    "reorder_rate": 0.02,
}
GARBAGE_EVERY = 50
READ_PACKETS = 10
TICK0 = 1_000_000


class MemoryLink:
    """A :class:`footnav.device.links.base.ByteLink` that ACKs each command and returns ``chunks``, one per read."""

    def __init__(self, chunks: list[bytes], name: str = "memory") -> None:
        from footnav.device.protocol.commands import CommandParser

        self._chunks = deque(chunks)
        self._answers: deque[bytes] = deque()
        self._parser = CommandParser()
        self._name = name

    @property
    def name(self) -> str:
        return self._name

    async def read(self) -> bytes:
        await asyncio.sleep(0)
        if self._answers:
            return self._answers.popleft()
        return self._chunks.popleft() if self._chunks else b""

    async def write(self, data: bytes) -> None:
        for cmd in self._parser.feed(data):
            if cmd.cmd_id != 0x01:  # host ACKs of data packets get no answer
                chk = 0xA0 + cmd.cmd_id
                self._answers.append(bytes((0xA0, cmd.cmd_id, chk >> 8, chk & 0xFF)))

    async def close(self) -> None:
        self._chunks.clear()


@dataclass
class Delivered:
    """What a unit driver delivered: counters, device ticks, values; and its link counts."""

    counter: np.ndarray
    ticks: np.ndarray
    acc: np.ndarray
    gyr: np.ndarray
    stats: Any


async def deliver(link: Any, *, command_set: Any = None) -> Delivered:
    """Start the calibrated IMU output on ``link`` and take every IMU batch until the stream ends."""
    from footnav.device.modes import NormalImuMode
    from footnav.device.unit import OpenShoeUnit
    from footnav.pipeline.samples import ImuBatch

    batches: list[ImuBatch] = []
    unit = OpenShoeUnit(link, command_set=command_set)
    await unit.start(NormalImuMode(0))
    async with contextlib.aclosing(unit.imu_batches()) as stream:
        async for batch in stream:
            batches.append(batch)
    stats = unit.stats
    b = ImuBatch.concat(batches)
    ticks = np.rint(b.t_s * 64e6).astype(np.int64) % (1 << 32)
    return Delivered(b.counter, ticks, b.acc_b_mps2, b.gyr_b_radps, stats)


def walk(seconds: float, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The demo's emulated walk at 1 kHz: times, specific force, angular rate."""
    from footnav.device.emulator.motion.gait import simulate_walk

    w = simulate_walk("rectangle", seconds, seed=seed)
    return w.t_s, w.acc_b_mps2, w.gyr_b_radps


def faulty_chunks(
    n: int, acc: np.ndarray, gyr: np.ndarray, faults: Any, seed: int = 3
) -> tuple[list[bytes], Any, np.ndarray]:
    """Packets 1..n (ticks from :data:`TICK0`, 1 kHz) through the fault injector, cut into reads of
    about :data:`READ_PACKETS` packets; the injector's log; the ticks sent."""
    from footnav.device.emulator.serving.faults import FaultInjector
    from footnav.device.protocol.imu import encode_packets

    ticks = (TICK0 + np.arange(n, dtype=np.int64) * 64_000) % (1 << 32)
    wire = encode_packets(np.arange(1, n + 1), ticks, acc[:n], gyr[:n])
    injector = FaultInjector(faults, seed=seed)
    out = b"".join(injector.apply(wire[k : k + 34 * 100])[0] for k in range(0, len(wire), 34 * 100))
    out += injector.flush()
    rng = np.random.default_rng(seed)
    chunks, i = [], 0
    while i < len(out):
        step = int(rng.integers(READ_PACKETS // 2, 3 * READ_PACKETS // 2 + 1)) * 34
        chunks.append(out[i : i + step])
        i += step
    return chunks, injector.log, ticks


def wrong_samples(d: Delivered, acc: np.ndarray, gyr: np.ndarray, ticks: np.ndarray) -> np.ndarray:
    """Mask of delivered samples whose counter, tick or values differ from what was sent as that number."""
    k = d.counter - 1
    inside = (k >= 0) & (k < len(ticks))
    kk = np.clip(k, 0, len(ticks) - 1)
    same = (
        inside
        & (d.ticks == ticks[kk])
        & (d.acc == acc[kk].astype(np.float32)).all(axis=1)
        & (d.gyr == gyr[kk].astype(np.float32)).all(axis=1)
    )
    return ~same


def pass_rate(ber: float, seconds: float, seed: int = 3) -> dict[str, Any]:
    """One row of the pass-rate table (see the module docstring)."""
    from footnav.device.emulator.serving.faults import WireFaults
    from footnav.device.protocol.commands import CommandSet

    _, acc, gyr = walk(seconds)
    n = len(acc)
    chunks, log, ticks = faulty_chunks(n, acc, gyr, WireFaults(bit_error_rate=ber), seed)
    d = asyncio.run(deliver(MemoryLink(chunks), command_set=CommandSet.V2015))
    wrong = wrong_samples(d, acc, gyr, ticks)
    k = np.clip(d.counter[wrong] - 1, 0, n - 1)
    err_acc = np.abs(d.acc[wrong] - acc[k].astype(np.float32)).max(initial=0.0)
    err_gyr = np.abs(d.gyr[wrong] - gyr[k].astype(np.float32)).max(initial=0.0)
    err_t = np.abs(d.ticks[wrong] - ticks[k]).max(initial=0) / 64e6
    s = d.stats
    return {
        "ber": ber,
        "packets": n,
        "corrupted": len(log.corrupted),
        "pass_checksum": len(log.undetected),
        "delivered": len(d.counter),
        "delivered_wrong": int(np.count_nonzero(wrong)),
        "corrupt_numbers": s.corrupt_numbers,
        "implausible": s.implausible_rejected,
        "lost": s.lost_packets,
        "max_err_acc": float(err_acc),
        "max_err_gyr": float(err_gyr),
        "max_err_t_s": float(err_t),
    }


def live_run(seconds: float, workdir: Path, *, speed: float = 1.0, seed: int = 5) -> dict[str, Any]:
    """``footnav live`` against the emulated unit with :data:`LIVE_FAULTS` and garbage; the accounting."""
    from footnav.device.emulator.serving.faults import WireFaults
    from footnav.device.emulator.serving.pty import DEFAULT_TICK0, PtyShoeServer
    from footnav.device.links.replay import CaptureReplayLink

    t, acc, gyr = walk(seconds, seed=2)
    faults = WireFaults(
        bit_error_rate=LIVE_FAULTS["bit_error_rate"],
        drop_rate=LIVE_FAULTS["drop_rate"],
        duplicate_rate=LIVE_FAULTS["duplicate_rate"],
        reorder_rate=LIVE_FAULTS["reorder_rate"],
    )
    server = PtyShoeServer(t, acc, gyr, speed=speed, faults=faults, garbage_every=GARBAGE_EVERY, seed=seed)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    cmd = [
        sys.executable,
        "-m",
        "footnav.app",
        "live",
        "--port",
        server.port,
        "--no-viewer",
        "--sessions",
        str(workdir),
    ]
    server.start()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 60 + 3 * seconds / speed
        while not server.finished.is_set():
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"footnav live ended or timed out before the emulator finished: {proc.poll()}")
            time.sleep(0.1)
        time.sleep(0.5)  # the last reads (footnav reads every 10 ms), before its 1 s idle watchdog
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        server.stop()
    if proc.returncode not in (0, 130) or server.error is not None:  # 130: stopped by Ctrl-C, cleanly
        raise RuntimeError(f"footnav live failed ({proc.returncode}, emulator: {server.error!r}):\n{err}")
    log = server.fault_log
    (capture,) = workdir.glob("live-*.mcap")
    d = asyncio.run(deliver(CaptureReplayLink(capture, "foot", speed=math.inf)))
    ticks = (DEFAULT_TICK0 + np.arange(len(t), dtype=np.int64) * 64_000) % (1 << 32)
    return {**account(d, log, acc, gyr, ticks), "stdout": out, "stderr": err}


def account(d: Delivered, log: Any, acc: np.ndarray, gyr: np.ndarray, ticks: np.ndarray) -> dict[str, Any]:
    """Every number the emulator sent: delivered once, or counted lost or rejected; values compared."""
    sent = log.packets_in
    counters = d.counter.tolist()
    delivered = set(counters)
    missing = set(range(1, sent + 1)) - delivered
    wrong = wrong_samples(d, acc, gyr, ticks)
    s = d.stats
    rejected = s.corrupt_numbers + s.implausible_rejected
    return {
        "sent": sent,
        "delivered": len(counters),
        "delivered_twice": len(counters) - len(delivered),
        "foreign": len(delivered - set(range(1, sent + 1))),
        "missing": len(missing),
        "missing_unexplained": len(missing - set(log.dropped) - set(log.corrupted)),
        "lost": s.lost_packets,
        "corrupt_numbers": s.corrupt_numbers,
        "implausible": s.implausible_rejected,
        "checksum_errors": s.checksum_errors,
        "duplicates": s.duplicates,
        # numbers neither delivered nor counted lost: at most the rejected packets stand for them
        "accounted": len(missing) - s.lost_packets <= rejected and len(missing) >= s.lost_packets,
        "dropped": len(log.dropped),
        "corrupted": len(log.corrupted),
        "pass_checksum": len(log.undetected),
        "delivered_wrong": int(np.count_nonzero(wrong)),
        "wrong_counters": d.counter[wrong].tolist(),
        "wrong_not_corrupted": len(set(d.counter[wrong].tolist()) - set(log.corrupted)),
        "max_err_acc": float(np.abs(d.acc[wrong] - acc[np.clip(d.counter[wrong] - 1, 0, len(acc) - 1)]).max(initial=0)),
        "max_err_gyr": float(np.abs(d.gyr[wrong] - gyr[np.clip(d.counter[wrong] - 1, 0, len(gyr) - 1)]).max(initial=0)),
    }


def summary_counts(stdout: str) -> dict[str, int]:
    """The numbers of ``footnav live``'s end-of-session line."""
    m = re.search(r"samples received: (\d+) \(lost packets: (\d+)", stdout)
    r = re.search(r"rejected: (\d+) corrupt numbers?, (\d+) implausible", stdout)
    return {
        "samples": int(m[1]) if m else -1,
        "lost": int(m[2]) if m else -1,
        "corrupt_numbers": int(r[1]) if r else 0,
        "implausible": int(r[2]) if r else 0,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.integrity", description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="walk per bit error rate (default 60)")
    parser.add_argument("--live", type=float, default=45.0, help="seconds of walk through footnav live (0: skip)")
    parser.add_argument("--speed", type=float, default=1.0, help="emulator speed for the live run (default 1)")
    args = parser.parse_args(argv)
    print(f"{'BER':>7}{'packets':>9}{'corrupted':>11}{'pass chk':>10}{'pass %':>9}{'delivered wrong':>17}"
          f"{'corrupt #':>11}{'implaus.':>10}{'max |Δacc|':>12}{'max |Δgyr|':>12}{'max |Δt| s':>12}")  # fmt: skip
    for ber in BERS:
        r = pass_rate(ber, args.seconds)
        pct = 100 * r["pass_checksum"] / max(1, r["corrupted"])
        print(f"{ber:>7.0e}{r['packets']:>9}{r['corrupted']:>11}{r['pass_checksum']:>10}{pct:>8.2f}%"
              f"{r['delivered_wrong']:>17}{r['corrupt_numbers']:>11}{r['implausible']:>10}"
              f"{r['max_err_acc']:>12.3g}{r['max_err_gyr']:>12.3g}{r['max_err_t_s']:>12.3g}")  # fmt: skip
    if args.live > 0:
        with tempfile.TemporaryDirectory() as tmp:
            r = live_run(args.live, Path(tmp), speed=args.speed)
        counts = summary_counts(r.pop("stdout"))
        r.pop("stderr")
        print(f"\nfootnav live, {args.live:g} s, {LIVE_FAULTS}, garbage every {GARBAGE_EVERY} packets:")
        for key, value in r.items():
            print(f"  {key:<22}{value}")
        print(f"  {'summary line':<22}{counts}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
