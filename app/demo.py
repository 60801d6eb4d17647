"""``footnav demo``: the emulated shoe on a pseudo-terminal, through the real serial path, end to end.

emulator (gait model + IMU errors) -> pty -> device layer -> pipeline -> Rerun, then a summary with
the distance walked and the final position error against the emulator's ground truth.
"""

from __future__ import annotations

import asyncio
import math
import sys
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.session import SerialSessionResult, run_serial_session
from app.status import StatusLine
from device.emulator.gait import GaitTruth, simulate_walk
from device.emulator.imu_errors import IMU_GRADES, corrupt
from device.emulator.pty_server import PtyShoeServer
from pipeline.navigator import NavConfig, Navigator
from pipeline.profiles import get_profile
from pipeline.runner import NavSink
from views.logger import RerunLogger
from views.sinks import choose_sinks

PATHS = ("rectangle", "line", "figure8", "stairs")
# the profile the filter assumes for each emulated sensor grade
PROFILE_OF_GRADE = {
    "mpu6500x4": "mpu6500x4",
    "adis16367": "adis16367",
    "icm20948": "generic",
    "gx3": "gx3",
    "ideal": "mpu6500x4",
}


@dataclass(frozen=True)
class DemoOptions:
    """What ``footnav demo`` was asked for."""

    path: str = "rectangle"
    duration_s: float = 60.0
    speed_mps: float = 1.4
    grade: str = "mpu6500x4"
    save: Path | None = None
    viewer: bool = True
    realtime: float = 1.0  # emulator pace: 1 = real time, math.inf = as fast as possible
    seed: int = 1


@dataclass(frozen=True)
class DemoSummary:
    """The figures the demo prints at the end."""

    distance_m: float
    final_error_m: float
    samples_expected: int
    samples_navigated: int
    lost_packets: int

    @property
    def error_percent(self) -> float:
        return 100.0 * self.final_error_m / self.distance_m if self.distance_m > 0 else math.nan

    def lines(self) -> list[str]:
        return [
            f"samples navigated: {self.samples_navigated} of {self.samples_expected} "
            f"(lost packets: {self.lost_packets})",
            f"distance walked:   {self.distance_m:.2f} m (ground truth)",
            f"final position error: {self.final_error_m:.3f} m = {self.error_percent:.2f} % of distance",
        ]


def summarise(truth: GaitTruth, result: SerialSessionResult, samples_navigated: int) -> DemoSummary | None:
    """Compare the last estimate with the ground truth of the same sample (matched by packet counter)."""
    nav = result.last_nav
    if nav is None or result.first_counter is None or result.link is None:
        return None
    # counters run one per sample at the 1 kHz base rate; the demo streams every sample
    last_index = round(float(nav.t_s[-1]) * truth.rate_hz)
    error = float(np.linalg.norm(nav.pos_n_m[-1] - truth.pos_n_m[last_index]))
    return DemoSummary(truth.distance_m, error, truth.t_s.size, samples_navigated, result.link.lost_packets)


def run_demo(opts: DemoOptions) -> int:
    """Run the demo; returns the process exit code."""
    if opts.path not in PATHS:
        raise ValueError(f"unknown path {opts.path!r}; choose one of {', '.join(PATHS)}")
    truth = simulate_walk(
        opts.path, opts.duration_s, rate_hz=1000.0, speed_mps=opts.speed_mps, seed=opts.seed
    )
    acc, gyr, _ = corrupt(
        truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, IMU_GRADES[opts.grade], seed=opts.seed
    )
    print(
        f"footnav demo: emulated shoe ({opts.grade}), {opts.path} walk, {opts.duration_s:.0f} s at "
        f"{opts.speed_mps:.1f} m/s, 1 kHz over a pseudo-terminal",
        file=sys.stderr,
    )
    sinks, note = choose_sinks(opts.save, want_viewer=opts.viewer)
    print(note, file=sys.stderr)
    logger = RerunLogger(sinks, recording_id=f"demo-{uuid.uuid4().hex[:12]}") if sinks else None
    if logger is not None:
        logger.log_truth(truth.pos_n_m, t_s=truth.t_s)
        logger.log_event(f"demo: {opts.path}, {opts.duration_s:.0f} s, grade {opts.grade}", t_s=0.0)
    config = NavConfig(profile=get_profile(PROFILE_OF_GRADE[opts.grade]))
    navigator = Navigator(config, rate_hz=truth.rate_hz)
    status = StatusLine()
    sinks_nav: list[NavSink] = [status] if logger is None else [logger.put, status]
    server = PtyShoeServer(truth.t_s, acc, gyr, speed=opts.realtime, record=False)
    interrupted = False
    result = SerialSessionResult()
    try:
        with server:
            asyncio.run(
                run_serial_session(
                    server.port,
                    navigator,
                    sinks_nav,
                    expect_samples=truth.t_s.size,
                    source_done=server.finished.is_set,
                    status=status,
                    result=result,
                )
            )
    except KeyboardInterrupt:
        interrupted = True
    finally:
        status.finish()
        if logger is not None:
            logger.close()
    if interrupted:
        print("interrupted: stopped the unit and closed the recording", file=sys.stderr)
    summary = summarise(truth, result, navigator.stats.samples_out)
    if summary is None:
        print("no navigation output (the unit never stood still long enough to align)", file=sys.stderr)
        return 1
    for line in summary.lines():
        print(line)
    return 0
