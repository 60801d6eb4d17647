"""``footnav demo --unit MODEL [--mode MODE]``: ``footnav live`` against an emulated unit of that model.

The emulated unit (``footnav.device.emulator.units``) walks at the model's base rate with its command
set and the outputs its firmware offers (the on-board INS states, the stepwise dead reckoning), on a
pseudo-terminal; the session is :func:`footnav.app.commands.live.live_session` itself, so what it shows
and captures is what a real unit of that model gives. The summary compares the last estimate with
the emulator's truth: the true position at that sample (IMU and INS output) or at the unit's last
filter reset (stepwise output).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import sys
from collections.abc import Callable

import numpy as np
from footnav.app.commands.live import LiveOptions, live_session
from footnav.app.feet import ONBOARD_TITLES
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.device.emulator.scripts import steps_from_truth, yaw_from_quat_wxyz
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.device.emulator.units import emulated_unit
from footnav.device.models import unit_model
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.runner import NavSink

SETTLE_S = 0.5
"""After the emulator has sent its last packet, the session runs this much longer (the last
lossless packets are ACKed, the last batches reach the views), s."""


async def _run(live: LiveOptions, finished: Callable[[], bool]) -> None:
    task = asyncio.create_task(live_session(live))
    while not finished() and not task.done():
        await asyncio.sleep(0.1)
    if not task.done():
        await asyncio.sleep(SETTLE_S)
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task


def final_error_m(truth: GaitTruth, last: NavBatch, output: str) -> float:
    """Horizontal distance of the last estimate from the truth it should match, m."""
    if output == "steps":
        steps = steps_from_truth(truth.t_s, truth.pos_n_m, yaw_from_quat_wxyz(truth.quat_nb_wxyz), truth.stance)
        return float(np.linalg.norm(last.pos_n_m[-1, :2] - steps.pos_n_m[-1, :2]))
    k = min(round(float(last.t_s[-1]) * truth.rate_hz), len(truth) - 1)
    return float(np.linalg.norm(last.pos_n_m[-1, :2] - truth.pos_n_m[k, :2]))


def run_unit_demo(
    *,
    model: str,
    output: str,
    path: str,
    duration_s: float,
    speed_mps: float,
    grade: str,
    seed: int,
    pace: float,
    live: Callable[[str], LiveOptions],
    collect: Callable[[str], NavSink] | None = None,
) -> int:
    """Run ``footnav live --unit model --mode output`` against the emulated unit; returns the exit code.

    ``live(port)`` makes the session's options for the emulated unit's port (viewer, capture, save).
    """
    m = unit_model(model)
    output = m.default_output if output == "auto" else output
    if output not in m.outputs:
        raise FootnavError(f"the {m.title} streams {', '.join(m.outputs)}, not --mode {output}")
    truth = simulate_walk(path, duration_s, rate_hz=m.base_rate_hz, speed_mps=speed_mps, seed=seed)
    acc, gyr, _ = corrupt(truth.acc_b_mps2, truth.gyr_b_radps, truth.rate_hz, IMU_GRADES[grade], seed=seed)
    print(
        f"footnav demo: an emulated {m.title} ({m.base_rate_hz:g} Hz, {m.command_set.value} command set, "
        f"{grade}), {path} walk, {duration_s:.0f} s at {speed_mps:.1f} m/s; footnav live --unit {m.name} "
        f"--mode {output} on it",
        file=sys.stderr,
    )
    got: list[NavBatch] = []

    def sink(foot: str) -> NavSink:
        extra = None if collect is None else collect(foot)

        def keep(nav: NavBatch) -> None:
            got.append(nav)
            if extra is not None:
                extra(nav)

        return keep

    with emulated_unit(m, truth, acc, gyr, speed=pace, record=False) as server:
        session = dataclasses.replace(live(server.port), collect=sink, output=output, model=m.name)
        try:
            asyncio.run(_run(session, server.finished.is_set))
        except KeyboardInterrupt:
            print("stopped: the recording was closed", file=sys.stderr)
            return 130
    if got:
        shown = "stepwise packets" if output == "steps" else "estimates"
        error_m = final_error_m(truth, got[-1], output)
        print(f"{sum(len(b) for b in got)} {shown} received; distance walked {truth.distance_m:.2f} m (ground truth)")
        share = 100 * error_m / max(truth.distance_m, 1e-9)
        # the emulated unit's own solution is the emulator's truth
        truth_sent = " (the emulated unit sends the true track as its own solution: this checks the decoding)"
        print(
            f"final position error: {error_m:.3f} m = {share:.2f} % of distance"
            + (truth_sent if output in ONBOARD_TITLES else "")
        )
    return 0
