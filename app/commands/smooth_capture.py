"""``footnav export CAPTURE --smooth`` (or ``--step-smoothing``): a footnav capture's session smoothed whole.

The capture is replayed through the same device decoding as ``footnav replay`` (the start handshake,
the rate the unit's clock gives, the unit's calibration file, the averaged raw IMUs), but the decoded
IMU samples are kept instead of navigated (:class:`SampleCollector`). The smoother of recordings then
runs over them with the navigator settings recorded in the capture, as ``footnav export`` smooths a
recording from another tool: the gyroscope's saturated stretches reconstructed first
(``footnav.pipeline.navigation.saturation``), then the RTS smoother of the whole session
(``footnav.pipeline.smoothing.rts``) or the step smoother (``footnav.pipeline.smoothing.stepwise``).

Refused (:func:`smoothing_refusal`): a ToF unit's capture (the smoothers store no floor states, so
they cannot take the ToF channel), a dual-IMU board's (they take one IMU), and a unit's own solution
(INS states or steps: there are no IMU samples to smooth).
"""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import numpy as np
from footnav.app.commands.replay import (
    FULL_SPEED_JOIN_SAMPLES,
    ReplayOptions,
    capture_calibration_lookup,
    captured_mode,
    checked_summary,
    onboard_outputs,
)
from footnav.app.config import Config, apply_capture_settings, defaults
from footnav.app.session import run_unit_session
from footnav.device.files.capture import CaptureSummary
from footnav.device.links.replay import CaptureReplayLink
from footnav.device.unit import OpenShoeUnit
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.navigator import NavConfig, NavStats
from footnav.pipeline.navigation.saturation import reconstruct_saturated_rates
from footnav.pipeline.samples import ImuBatch


class SampleCollector:
    """What ``run_unit_session`` drives in place of a navigator: it keeps the IMU batches and estimates
    nothing.

    Parameters
    ----------
    rate_hz
        the rate the capture's header says the unit was asked for, Hz (the unit's clock may correct
        it: :meth:`retime`).
    """

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.batches: list[ImuBatch] = []

    def process(self, batch: ImuBatch) -> NavBatch | None:
        """Keep ``batch``; no estimate."""
        self.batches.append(batch)
        return None

    def retime(self, rate_hz: float) -> None:
        """The rate the unit's clock gives, Hz."""
        self.rate_hz = rate_hz


def smoothing_refusal(summary: CaptureSummary) -> str | None:
    """Why the capture's session cannot be smoothed, in words, or None if it can."""
    if onboard_outputs(summary):
        return "it holds the unit's own solution (INS states or steps), not IMU samples to smooth"
    for unit in summary.info.units:
        if unit.settings.get("extensions"):
            return "its unit has ToF sensors, and the smoothers do not take the ToF channel"
        if "dual_imu_lever_b_m" in unit.settings:
            return "it is a dual-IMU board's, and the smoothers take one IMU"
    return None


def smooth_capture(source: Path, smooth: str) -> dict[str, tuple[NavBatch, NavStats]]:
    """Each foot's smoothed session (``smooth``: ``whole`` or ``step``, as for recordings), with the
    navigator settings recorded in the capture; a foot that never stood still long enough to align is
    left out.

    Raises
    ------
    FootnavError
        the capture cannot be smoothed (:func:`smoothing_refusal`), or is not a capture to replay.
    """
    cfg = defaults()
    summary = checked_summary(ReplayOptions(path=source, config=cfg, viewer=False))
    why = smoothing_refusal(summary)
    if why is not None:
        raise FootnavError(
            f"{source} is a footnav capture whose session cannot be smoothed (--smooth, --step-smoothing): {why}; "
            "drop it for the live estimates"
        )
    info = summary.info
    recorded = info.units[0].settings.get("nav_config") if info.units else None
    if isinstance(recorded, dict):  # one settings set for all feet (they were one session), as replay takes it
        apply_capture_settings(cfg, recorded, f"capture {source.name}")
    config = cfg.nav_config()
    out: dict[str, tuple[NavBatch, NavStats]] = {}
    for foot, collector in captured_samples(source, summary, cfg).items():
        smoothed = _smooth(collector, config, smooth)
        if smoothed is not None:
            out[foot] = smoothed
    return out


def captured_samples(source: Path, summary: CaptureSummary, cfg: Config) -> dict[str, SampleCollector]:
    """Each foot's IMU samples, decoded as ``footnav replay`` decodes them (module docstring) and kept, not
    navigated (also ``footnav.app.api.navigation.read_recording``)."""
    ends = {
        foot: next((e.get("samples") for e in events if e.get("event") == "end"), None)
        for foot, events in summary.events.items()
    }
    out: dict[str, SampleCollector] = {}
    for unit in summary.info.units:
        settings = unit.settings
        collector = SampleCollector(float(settings.get("rate_hz", 1000.0)))
        link = CaptureReplayLink(source, unit.foot, speed=math.inf)
        expect = ends.get(unit.foot)
        asyncio.run(
            run_unit_session(
                OpenShoeUnit(link),
                collector,
                [],
                start=True,  # the same handshake as live: the unit's answers are in the capture
                rate_divider_log2=int(settings.get("rate_divider_log2", 0)),
                expect_samples=expect if isinstance(expect, int) else None,
                idle_notice_s=None,
                calibration=capture_calibration_lookup(summary, cfg, unit.foot),
                join_samples=FULL_SPEED_JOIN_SAMPLES,
                mode=captured_mode(settings, None, dual=False),
                fuse_imus=isinstance(settings.get("fused_imu_mask"), int),
            )
        )
        out[unit.foot] = collector
    return out


def _smooth(collector: SampleCollector, config: NavConfig, smooth: str) -> tuple[NavBatch, NavStats] | None:
    """The collected samples smoothed (None: none collected, or never still long enough to align)."""
    if not collector.batches:
        return None
    t_s = np.concatenate([b.t_s for b in collector.batches])
    acc = np.concatenate([b.acc_b_mps2 for b in collector.batches])
    gyr = np.concatenate([b.gyr_b_radps for b in collector.batches])
    sat = reconstruct_saturated_rates(t_s, gyr)
    if smooth == "whole":
        from footnav.pipeline.smoothing.rts import smooth_recording

        nav, stats = smooth_recording(t_s, acc, sat.gyr_b_radps, collector.rate_hz, config, gyr_clipped_b=sat.clipped_b)
    else:
        from footnav.pipeline.smoothing.stepwise import step_smooth_recording

        nav, stats = step_smooth_recording(
            t_s, acc, sat.gyr_b_radps, collector.rate_hz, config, gyr_clipped_b=sat.clipped_b
        )
    if nav is None:
        return None
    stats.rates_reconstructed = sat.reconstructed
    stats.rates_clipped = int(np.count_nonzero(sat.clipped_b))
    return nav, stats
