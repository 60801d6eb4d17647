"""``python -m benchmarks.lsl``: what ``--lsl`` costs the pipeline, as a ratio to navigating the same samples.

An emulated walk (``--minutes``, 1 kHz, the demo's rectangle and MPU-6500-class errors) is navigated by
``Navigator`` in batches of ``--batch`` samples, as a live 1 kHz unit's reads arrive (the baseline, with the
gait events filled as a session fills them); then the same NavBatches are pushed through
``footnav.views.lsl.LslOutlets.put``, as the ``--lsl`` sink does, with a real pylsl inlet on loopback pulling
both streams in a thread (so liblsl queues and sends every sample). Both are the best of ``--repeats`` runs by
the wall clock; the table gives samples per second and LSL's time as a share of the navigator's. The inlet's
sample count is checked against what was pushed.
"""

from __future__ import annotations

import argparse
import threading
import time
from typing import Any

import numpy as np
from footnav.device.emulator.motion.gait import simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.pipeline.gait.events import GaitEventTracker
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavConfig, Navigator
from footnav.pipeline.samples import ImuBatch
from footnav.views.lsl import LslFoot, import_pylsl, open_lsl

RATE_HZ = 1000.0


def navigated(minutes: float, batch: int) -> tuple[list[NavBatch], float]:
    """The walk's NavBatches (gait events filled) and the wall time the navigator took, s."""
    truth = simulate_walk("rectangle", minutes * 60.0, RATE_HZ, seed=1)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, RATE_HZ, "mpu6500x4", seed=2)
    n = len(truth)
    counter, host = np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    nav, events, out = Navigator(NavConfig(), RATE_HZ), GaitEventTracker(), []
    start = time.perf_counter()
    for a in range(0, n, batch):
        b = a + batch
        est = nav.process(ImuBatch(truth.t_s[a:b], acc[a:b], gyr[a:b], counter[a:b], host[a:b]))
        if est is not None and len(est):
            out.append(events.annotate(est))
    return out, time.perf_counter() - start


def pushed(pylsl: Any, batches: list[NavBatch]) -> tuple[float, int]:
    """Wall time of pushing ``batches`` through fresh outlets, s, and how many samples an inlet received."""
    outlets = open_lsl([LslFoot("foot", "benchmark", "emulator", RATE_HZ)])
    (info,) = pylsl.resolve_byprop("source_id", "footnav:benchmark:foot", 1, 10.0)
    inlet = pylsl.StreamInlet(info, max_buflen=3600)
    inlet.open_stream(timeout=10.0)
    received, done = [0], threading.Event()

    def pull() -> None:
        while not done.is_set() or inlet.samples_available():
            _, stamps = inlet.pull_chunk(timeout=0.05, max_samples=100_000)
            received[0] += len(stamps)

    reader = threading.Thread(target=pull, daemon=True)
    reader.start()
    start = time.perf_counter()
    for nav in batches:
        outlets.put(nav, foot="foot")
    elapsed = time.perf_counter() - start
    time.sleep(1.0)  # the last chunks reach the inlet
    done.set()
    reader.join(timeout=10.0)
    outlets.close()
    return elapsed, received[0]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.lsl", description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=2.0, help="walk length (default 2)")
    p.add_argument("--batch", type=int, default=30, help="samples per batch (default 30: a read at 1 kHz)")
    p.add_argument("--repeats", type=int, default=3, help="best of this many runs (default 3)")
    args = p.parse_args(argv)
    pylsl = import_pylsl()
    navigated(0.1, args.batch)  # compile or load the kernels
    nav_s = min(navigated(args.minutes, args.batch)[1] for _ in range(args.repeats))
    batches, _ = navigated(args.minutes, args.batch)
    n = sum(len(b) for b in batches)
    runs = [pushed(pylsl, batches) for _ in range(args.repeats)]
    lsl_s = min(r[0] for r in runs)
    print(f"LSL cost, {args.minutes:g} min at 1 kHz in {args.batch}-sample batches ({n} samples navigated)\n")
    print(f"  {'navigator (baseline)':28s} {n / nav_s:12,.0f} samples/s")
    print(f"  {'LslOutlets.put':28s} {n / lsl_s:12,.0f} samples/s   {lsl_s / nav_s:6.1%} of the navigator's time")
    print(f"  inlet received {', '.join(str(r[1]) for r in runs)} of {n} samples per run")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
