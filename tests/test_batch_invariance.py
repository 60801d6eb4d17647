"""A live session's estimates do not depend on how the stream is cut into batches: the unit's reads
(whose sizes follow the serial port's timing) and a replay's joined reads give the same estimates, bit
for bit. Each test feeds the same samples in one batch and in other batchings and compares every field.
Found by a search for such dependences after a 1-ULP difference between a live session and its replay
(the calibration's correction, now in tests/test_calibration.py)."""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable, Iterator

import numpy as np
import pytest
from footnav.app.experiments import tof as tof_experiment
from footnav.pipeline.aiding.tof_types import RangeBatch, TofConfig
from footnav.pipeline.nav_types import NavBatch
from footnav.pipeline.navigation.lead_in import LiveLeadIn
from footnav.pipeline.navigation.navigator import NavConfig, Navigator
from footnav.pipeline.samples import ImuBatch
from test_lead_in_live import walk_then_rest

RATE_HZ = 1000.0


def pieces(n: int, size: int | None, seed: int = 1) -> Iterator[tuple[int, int]]:
    """Batches (start, end): one batch (None), or batches of random sizes 1..``size``."""
    if size is None:
        yield 0, n
        return
    rng = np.random.default_rng(seed)
    bounds = [0]
    while bounds[-1] < n:
        bounds.append(min(n, bounds[-1] + int(rng.integers(1, size + 1))))
    yield from itertools.pairwise(bounds)


def per_sample_fields(batches: list[NavBatch]) -> dict[str, np.ndarray]:
    """Every per-sample array of the estimates (and of the ToF readings' outcomes), joined."""
    fields: dict[str, np.ndarray] = {}
    for f in dataclasses.fields(NavBatch):
        values = [getattr(b, f.name) for b in batches if getattr(b, f.name) is not None]
        if values and isinstance(values[0], np.ndarray):
            fields[f.name] = np.concatenate(values)
        elif values and dataclasses.is_dataclass(values[0]):
            for g in dataclasses.fields(values[0]):
                parts = [getattr(v, g.name) for v in values]
                if all(isinstance(p, np.ndarray) for p in parts):
                    fields[f"{f.name}.{g.name}"] = np.concatenate(parts)
    return fields


def assert_same(a: list[NavBatch], b: list[NavBatch]) -> None:
    fa, fb = per_sample_fields(a), per_sample_fields(b)
    assert fa.keys() == fb.keys()
    assert len(fa["t_s"]) > 0
    for name in fa:
        np.testing.assert_array_equal(fa[name], fb[name], err_msg=name)  # NaN equals NaN here


def imu_batch(acc: np.ndarray, gyr: np.ndarray) -> ImuBatch:
    n = acc.shape[0]
    return ImuBatch(np.arange(n) / RATE_HZ, acc, gyr, np.arange(n, dtype=np.int64), np.arange(n, dtype=np.int64) * 1000)


@pytest.fixture(scope="module")
def stairs() -> tuple[ImuBatch, RangeBatch]:
    rec = tof_experiment.record("stairs", 20.0, seed=1)
    return imu_batch(rec.acc_b_mps2, rec.gyr_b_radps), rec.ranges


def _tof_navigator() -> Navigator:
    return Navigator(NavConfig(), RATE_HZ, tof=TofConfig())


def _reads(imu: ImuBatch, ranges: RangeBatch, size: int | None) -> Iterator[tuple[ImuBatch, RangeBatch]]:
    """The unit's reads: IMU samples, then the ToF readings sent before the read's last sample."""
    lo = 0
    for a, b in pieces(len(imu), size):
        hi = len(ranges.t_s) if b == len(imu) else int(np.searchsorted(ranges.t_s, imu.t_s[b - 1], side="right"))
        yield imu.select(slice(a, b)), RangeBatch(*(x[lo:hi] for x in dataclasses.astuple(ranges)))
        lo = hi


@pytest.mark.parametrize("size", [7, 120])
def test_tof_aiding_on_stairs_whatever_the_batches(stairs: tuple[ImuBatch, RangeBatch], size: int) -> None:
    """Readings due before a batch's first sample take the previous sample's stance; the floor under
    the IMU takes the levels' heights as of the last reading, not as of the batch's end."""

    def run(size: int | None) -> list[NavBatch]:
        nav, out = _tof_navigator(), []
        for imu, readings in _reads(*stairs, size):
            if len(readings.t_s):
                nav.add_ranges(readings)  # on time: before the samples they precede
            if (got := nav.process(imu)) is not None:
                out.append(got)
        return out

    assert_same(run(None), run(size))


def test_a_reading_at_a_batchs_start_takes_the_previous_samples_stance() -> None:
    """The ``and`` detector (inertial and height): a reading due before a batch's first sample is
    applied with the stance of the sample before it, not of the batch's first."""
    rec = tof_experiment.record("line", 40.0, seed=1)
    imu = imu_batch(rec.acc_b_mps2, rec.gyr_b_radps)
    cfg = TofConfig()
    tof = dataclasses.replace(cfg, detector=dataclasses.replace(cfg.detector, mode="and"))

    def run(size: int | None) -> list[NavBatch]:
        nav, out = Navigator(NavConfig(), RATE_HZ, tof=tof), []
        for part, readings in _reads(imu, rec.ranges, size):
            if len(readings.t_s):
                nav.add_ranges(readings)
            if (got := nav.process(part)) is not None:
                out.append(got)
        return out

    assert_same(run(None), run(2))


def test_tof_aiding_live_reads_equal_the_replays_joined_reads(stairs: tuple[ImuBatch, RangeBatch]) -> None:
    """Live, readings arrive after the samples of their read; a full-speed replay joins reads without
    readings into one batch (``footnav.device.links.capture_replay``). Some reads carry no reading."""
    reads = list(_reads(*stairs, 40))
    assert sum(len(r.t_s) == 0 for _, r in reads) > 10

    def run(join: bool) -> list[NavBatch]:
        nav, out, held = _tof_navigator(), [], []

        def process(imu: list[ImuBatch]) -> None:
            if imu and (got := nav.process(ImuBatch.concat(imu))) is not None:
                out.append(got)

        for imu, readings in reads:
            held.append(imu)
            if not join or len(readings.t_s):
                process(held)
                held = []
            if len(readings.t_s):
                nav.add_ranges(readings)
        process(held)
        return out

    assert_same(run(join=False), run(join=True))


def _stream(nav_make: Callable[[], Navigator], imu: ImuBatch, size: int | None) -> list[NavBatch]:
    nav, out = nav_make(), []
    for a, b in pieces(len(imu), size):
        if (got := nav.process(imu.select(slice(a, b)))) is not None:
            out.append(got)
    return out


@pytest.mark.parametrize("pause_samples", [700, 800])
def test_alignment_on_a_short_pause_whatever_the_batches(pause_samples: int) -> None:
    """A pause a little longer than the alignment window, between two stretches of motion: in a
    stream, the quiet flags of the last half window are not final (the window's mean is cut short)
    and made the pause look long enough; the whole recording does not align there."""
    rng = np.random.default_rng(0)

    def stretch(moving: bool, m: int) -> tuple[np.ndarray, np.ndarray]:
        acc_sd, gyr_sd = (5.0, 3.0) if moving else (0.02, 0.005)
        return np.array([0.0, 0.0, 9.81]) + rng.normal(0, acc_sd, (m, 3)), rng.normal(0, gyr_sd, (m, 3))

    parts = [stretch(True, 3000), stretch(False, pause_samples), stretch(True, 3000), stretch(False, 3000)]
    imu = imu_batch(np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts]))
    whole = _stream(lambda: Navigator(NavConfig(), RATE_HZ), imu, None)
    assert len(whole[0].t_s) < len(imu) - 6000  # aligned on the final rest, not on the pause
    for size in (10, 120):
        assert_same(whole, _stream(lambda: Navigator(NavConfig(), RATE_HZ), imu, size))


def test_a_lead_in_before_a_long_still_period_whatever_the_batches() -> None:
    """Six strides, then 14 s still (longer than ``LEAD_IN_STILL_S``), then a walk: the backward run
    starts at a fixed point of the still period, not where the samples held at the check end."""
    _, acc, gyr = walk_then_rest(22.0, 6, 6.0, 1.0)
    imu = imu_batch(acc, gyr)

    def run(size: int | None) -> tuple[list[NavBatch], list[NavBatch]]:
        nav = Navigator(NavConfig(), RATE_HZ)
        lead_in, forward, filled = LiveLeadIn(nav), [], []
        for a, b in pieces(len(imu), size):
            part = imu.select(slice(a, b))
            lead_in.add(part)
            if (got := nav.process(part)) is not None:
                forward.append(got)
            filled += [x for x in (lead_in.after(got),) if x is not None]
        filled += [x for x in (lead_in.finish(),) if x is not None]
        return forward, filled

    forward, filled = run(None)
    assert len(filled) == 1 and len(filled[0].t_s) > 1000  # the strides before the still period, backwards
    for size in (30, 5000):
        other_forward, other_filled = run(size)
        assert_same(forward, other_forward)
        assert_same(filled, other_filled)


def test_a_whole_recording_aligns_on_a_short_still_period_at_its_end() -> None:
    """``navigate`` on whole arrays: the quiet flags at the recording's end are final, and a stream's
    caution (its last half window) does not apply: 0.7 s of rest after 3 s of motion is enough."""
    from footnav.pipeline.navigation.navigator import navigate

    rng = np.random.default_rng(0)
    gravity = np.array([0.0, 0.0, 9.81])
    acc = np.vstack([gravity + rng.normal(0, 5.0, (3000, 3)), gravity + rng.normal(0, 0.02, (700, 3))])
    gyr = np.vstack([rng.normal(0, 3.0, (3000, 3)), rng.normal(0, 0.005, (700, 3))])
    nav, _ = navigate(np.arange(3700) / RATE_HZ, acc, gyr, RATE_HZ)
    assert nav is not None and 0 < len(nav.t_s) < 700
    streamed = _stream(lambda: Navigator(NavConfig(), RATE_HZ), imu_batch(acc, gyr), 100)
    assert streamed == []  # a stream does not know its last samples are its last
