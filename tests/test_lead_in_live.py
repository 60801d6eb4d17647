"""A live session that starts in motion: its lead-in kept, navigated backwards once the navigator has
aligned and its still period has ended (``footnav.pipeline.navigation.lead_in.LiveLeadIn``), and handed
to the views as one more batch; the same estimates as the batch path's, the forward ones untouched."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pytest
from footnav.app import read_recording
from footnav.app.commands import demo
from footnav.app.commands.demo import DemoOptions, demo_config, run_demo
from footnav.app.commands.export import run_export
from footnav.app.commands.replay import ReplayOptions, checked_summary, run_replay
from footnav.app.commands.smooth_capture import captured_samples
from footnav.app.config import defaults
from footnav.app.feet import FOOT_START_OFFSET_M
from footnav.device.emulator.motion.gait import FOOT_SIDE_M, GaitTruth, simulate_walk
from footnav.device.emulator.sensors.imu_errors import corrupt
from footnav.pipeline.gait.events import GaitEventTracker
from footnav.pipeline.nav_types import NavBatch, concat_batches
from footnav.pipeline.navigation.lead_in import LiveLeadIn, navigate_every_sample
from footnav.pipeline.navigation.navigator import NavConfig, Navigator
from footnav.pipeline.navigation.profiles import get_profile
from footnav.pipeline.samples import ImuBatch
from footnav.views.plan import DecimatedLine
from footnav.views.strides import StrideTable
from rerun.chunk import RrdReader

RATE_HZ = 1000.0
CONFIG = NavConfig(profile=get_profile("mpu6500x4"))
ESTIMATES = ("t_s", "pos_n_m", "vel_n_mps", "quat_nb_wxyz", "pos_cov_n_m2", "cov_pos_yaw", "stance",
             "detector_stat", "detector_threshold", "clearance_m")  # fmt: skip


def assert_same(a: NavBatch, b: NavBatch) -> None:
    assert len(a) == len(b)
    for name in ESTIMATES:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)  # bit for bit


def walk_then_rest(
    first_s: float, strides: int, second_s: float, second_still_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``strides`` strides from mid-motion, rest until ``first_s``, then a walk of ``second_s`` that starts
    with ``second_still_s`` still: the first still period lies between the two walks (the foot stands level
    at rest, so the body-frame signals join). Times (n,) s, specific force and rate (n, 3), 1 kHz."""
    first = simulate_walk("rectangle", first_s, rate_hz=RATE_HZ, seed=2, initial_still_s=0.0, max_strides=strides)
    second = simulate_walk("rectangle", second_s, rate_hz=RATE_HZ, seed=5, initial_still_s=second_still_s)
    acc, gyr, _ = corrupt(
        np.vstack([first.acc_b_mps2, second.acc_b_mps2]),
        np.vstack([first.gyr_b_radps, second.gyr_b_radps]),
        RATE_HZ,
        "mpu6500x4",
        seed=3,
    )
    return np.arange(acc.shape[0]) / RATE_HZ, acc, gyr


@pytest.fixture(scope="module")
def walk_rest_walk() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """8 strides, a rest of about 7 s, then a second walk (:func:`walk_then_rest`)."""
    return walk_then_rest(14.0, 8, 10.0, 1.5)


def stream(
    t: np.ndarray, acc: np.ndarray, gyr: np.ndarray, arrivals: list[NavBatch] | None = None, **kw: float
) -> tuple[NavBatch, list[tuple[int, NavBatch]], Navigator]:
    """The samples through a navigator in batches of 10, as a session gives them; the forward estimates,
    and each lead-in with the number of samples given when it came (``arrivals``: every batch, in the
    order a session's sinks get them: a lead-in before the batch whose navigation brought it)."""
    nav = Navigator(CONFIG, RATE_HZ)
    fill = LiveLeadIn(nav, **kw)
    forward, lead_ins = [], []
    arrivals = [] if arrivals is None else arrivals
    for a in range(0, t.size, 10):
        k = np.arange(a, min(t.size, a + 10))
        batch = ImuBatch(t[k], acc[k], gyr[k], k.astype(np.int64), np.full(k.size, 1000 + a, np.int64))
        fill.add(batch)
        out = nav.process(batch)
        if (lead_in := fill.after(out)) is not None:
            lead_ins.append((int(k[-1]) + 1, lead_in))
            arrivals.append(lead_in)
        if out is not None:
            forward.append(out)
            arrivals.append(out)
    if (lead_in := fill.finish()) is not None:
        lead_ins.append((t.size, lead_in))
        arrivals.append(lead_in)
    return concat_batches(forward), lead_ins, nav


def test_the_lead_in_is_filled_in_once_the_still_period_ends(walk_rest_walk) -> None:  # type: ignore[no-untyped-def]
    """Measured: 8232 samples of lead-in (the 8 strides), the still period to sample 15322, filled in
    at sample 16230 (0.9 s later: a window of 0.5 s to decide the last quiet flag, and a look every
    0.5 s): the batch path's estimates, bit for bit; the forward ones as without it."""
    t, acc, gyr = walk_rest_walk
    whole, stats = navigate_every_sample(t, acc, gyr, RATE_HZ, CONFIG)
    assert whole is not None and len(whole) == t.size
    s = stats.samples_before_alignment
    assert s == stats.samples_navigated_backwards > 8000
    forward, lead_ins, nav = stream(t, acc, gyr)
    ((given, lead_in),) = lead_ins
    assert 15322 + 500 <= given <= 15322 + 1500  # after the still period, not at the end of the stream
    assert_same(lead_in, _part(whole, 0, s))
    np.testing.assert_array_equal(lead_in.host_ns, 1000 + np.arange(s) // 10 * 10)  # the samples' own
    assert_same(forward, _part(whole, s, t.size))
    alone = Navigator(CONFIG, RATE_HZ).process(ImuBatch(t, acc, gyr, np.arange(t.size), np.zeros(t.size, np.int64)))
    assert alone is not None
    assert_same(forward, alone)
    assert nav.stats.samples_navigated_backwards == s and nav.stats.samples_out == t.size


def test_a_still_period_that_lasts_is_not_waited_for(walk_rest_walk) -> None:  # type: ignore[no-untyped-def]
    """``still_s`` 1 s: filled in from the first 1.0 s of the 7 s still period, at the first look (every
    alignment window, 0.5 s, from the alignment) once the window after it has come; measured 6.5 mm at
    most from the batch path's lead-in (which takes all 7 s) over its 11.8 m, whose 1σ at its first
    sample is 2.5 cm."""
    t, acc, gyr = walk_rest_walk
    whole, stats = navigate_every_sample(t, acc, gyr, RATE_HZ, CONFIG)
    assert whole is not None
    s = stats.samples_before_alignment
    _, lead_ins, _ = stream(t, acc, gyr, still_s=1.0)
    ((given, lead_in),) = lead_ins
    assert s + 1500 <= given <= s + 1500 + 500 + 10  # a look every 500 samples, batches of 10
    err = np.linalg.norm(lead_in.pos_n_m - whole.pos_n_m[:s], axis=1)
    assert 0 < err.max() < 0.01 < math.sqrt(np.trace(whole.pos_cov_n_m2[0]))


def test_samples_beyond_the_bound_stay_not_navigated(walk_rest_walk) -> None:  # type: ignore[no-untyped-def]
    """``keep_s`` 3 s: only the samples of the last 3 s before the alignment are kept, and those of the
    lead-in among them (2492) navigated, the same as the
    batch path's (to 1e-9 m: the reversed clock starts elsewhere); the rest are counted as not navigated."""
    t, acc, gyr = walk_rest_walk
    whole, stats = navigate_every_sample(t, acc, gyr, RATE_HZ, CONFIG)
    assert whole is not None
    s = stats.samples_before_alignment
    _, lead_ins, nav = stream(t, acc, gyr, keep_s=3.0)
    ((_, lead_in),) = lead_ins
    kept = len(lead_in)
    # the 3 s before the navigator aligned hold the still period's first half second and more
    assert 2000 < kept < 3000 - 500 and nav.stats.samples_navigated_backwards == kept
    assert nav.stats.samples_before_alignment == s
    np.testing.assert_array_equal(lead_in.t_s, t[s - kept : s])
    np.testing.assert_allclose(lead_in.pos_n_m, whole.pos_n_m[s - kept : s], rtol=0, atol=1e-9)


def test_the_views_draw_the_lead_in_and_count_its_strides(walk_rest_walk) -> None:  # type: ignore[no-untyped-def]
    """The lead-in reaches the views after the forward batches of the first 0.9 s past the still period:
    the decimated track line (3D and plan) takes it in front of them, and the stride table adds its
    strides before theirs. Measured: 7 lead-in strides and 6 after the rest, each 1.44 m (before: the
    line began at the alignment and the table held the 6 only)."""
    t, acc, gyr = walk_rest_walk
    arrivals: list[NavBatch] = []
    forward, ((_, lead_in),), _ = stream(t, acc, gyr, arrivals)
    steps, lead_in_steps = GaitEventTracker(), GaitEventTracker()  # as FootRun.lead_in_sink: one of its own
    shown = [lead_in_steps.annotate(b) if b is lead_in else steps.annotate(b) for b in arrivals]
    line, table = DecimatedLine([]), StrideTable(("foot",))
    for nav in shown:
        line.add(nav.t_s, nav.pos_n_m.astype(np.float32))
        table.update("foot", nav)
    assert line.points[0] == tuple(float(v) for v in lead_in.pos_n_m[0].astype(np.float32))
    assert line.points[-1] in {tuple(float(v) for v in p) for p in forward.pos_n_m[-100:].astype(np.float32)}
    assert len(line.points) == 241  # 0.1 s apart over 24.1 s: the lead-in's 8.2 s, the rest's and the walk's
    k = next(i for i, b in enumerate(arrivals) if b is lead_in)
    alone = [StrideTable(("foot",)) for _ in range(2)]
    for i, nav in enumerate(shown):
        alone[i != k].update("foot", nav)
    before, after = (a.strides("foot") for a in alone)
    assert len(before) == 7 and len(after) == 6
    assert table.strides("foot") == before + after
    assert all(1.3 < s.length_m < 1.6 for s in table.strides("foot"))


def _part(nav: NavBatch, a: int, b: int) -> NavBatch:
    """Samples ``[a, b)`` of ``nav``'s per-sample estimates."""
    return dataclasses.replace(nav, **{f: getattr(nav, f)[a:b] for f in ESTIMATES if getattr(nav, f) is not None})


def _footnav(*args: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    return subprocess.run(
        [sys.executable, "-m", "footnav.app", *args], capture_output=True, text=True, timeout=300, env=env, check=False
    )


def test_a_demo_that_starts_in_motion_through_the_session_and_its_replay(tmp_path: Path) -> None:
    """The emulated shoe walks from its first sample (20 s, 14.6 s of strides, then it stands): the
    still period lasts to the end of the stream, where the lead-in is filled in. It reaches the
    session's sinks and its .rrd, equals the batch path's on the samples the session navigated, and a
    replay of the capture (in process, and ``footnav replay --save``) gives it again."""
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    got: dict[str, list[NavBatch]] = {}
    rrd = tmp_path / "live.rrd"
    opts = DemoOptions(
        duration_s=20.0,
        viewer=False,
        save=rrd,
        realtime=math.inf,
        config=cfg,
        initial_still_s=0.0,
        collect=lambda foot: got.setdefault(foot, []).append,
    )
    assert run_demo(opts) == 0
    *forward_batches, lead_in = got["foot"]
    forward = concat_batches(forward_batches)
    assert float(lead_in.t_s[-1]) < float(forward.t_s[0])  # one batch, after the ones it precedes
    assert len(lead_in) + len(forward) == 20_000
    assert lead_in.step_onsets is not None and lead_in.step_onsets.size > 10  # its steps found
    (capture,) = tmp_path.glob("*.mcap")
    rec = read_recording(capture)
    whole, stats = navigate_every_sample(
        rec.t_s, rec.acc_b_mps2, rec.gyr_b_radps, rec.rate_hz, demo_config(DemoOptions(config=defaults())).nav_config()
    )
    assert whole is not None and stats.samples_navigated_backwards == len(lead_in) > 14_000
    assert_same(lead_in, _part(whole, 0, len(lead_in)))
    assert_same(forward, _part(whole, len(lead_in), len(whole)))
    # the replay in process: the same batches
    again: dict[str, list[NavBatch]] = {}
    replay = ReplayOptions(
        path=capture, config=defaults(), viewer=False, collect=lambda f: again.setdefault(f, []).append
    )
    assert run_replay(replay) == 0
    *replayed, replayed_lead_in = again["foot"]
    assert_same(replayed_lead_in, lead_in)
    assert_same(concat_batches(replayed), forward)
    # exported, in time order
    table = tmp_path / "track.csv"
    run_export(capture, table, fmt=None, columns=None, profile=None, smooth=None)
    rows = np.loadtxt(table, delimiter=",", skiprows=1, usecols=(0, 1, 2, 3))
    assert rows.shape[0] == 20_000
    np.testing.assert_allclose(rows[:, 0], np.concatenate([lead_in.t_s, forward.t_s]), rtol=0, atol=1e-6)
    np.testing.assert_allclose(rows[: len(lead_in), 1:], lead_in.pos_n_m, rtol=0, atol=1e-6)
    # the command line: the summary counts it, the recording holds every sample at its time
    saved = tmp_path / "replay.rrd"
    proc = _footnav("replay", str(capture), "--no-viewer", "--save", str(saved))
    assert proc.returncode == 0, proc.stderr
    m = re.search(r"navigated: (\d+) of (\d+) replayed .*distance ([\d.]+) m; (\d+) samples before the", proc.stdout)
    assert m and int(m[1]) == int(m[2]) == 20_000 and int(m[4]) == len(lead_in), proc.stdout
    assert 23.0 < float(m[3]) < 27.0  # the lead-in's strides counted: 25.8 m of track, 23.6 m walked
    for path in (rrd, saved):
        track = (
            RrdReader(path).stream().collect().reader(index="imu_time", contents=["/world/foot/track"]).to_arrow_table()
        )
        t_ns = np.asarray(track["imu_time"].cast("int64").to_numpy())
        pos = np.asarray(pc.list_flatten(pc.list_flatten(track["/world/foot/track:Points3D:positions"])).to_numpy())
        pos = pos.reshape(-1, 3)
        assert track.num_rows == 20_000
        order = np.argsort(t_ns, kind="stable")
        np.testing.assert_allclose(t_ns[order][: len(lead_in)], lead_in.t_s * 1e9, rtol=0, atol=1.0)  # ns
        np.testing.assert_array_equal(pos[order][: len(lead_in)], lead_in.pos_n_m.astype(np.float32))


def _walking_from_the_first_sample(
    path: str, duration_s: float, rate_hz: float = 1000.0, speed_mps: float = 1.4, *, seed: int = 0
) -> tuple[GaitTruth, GaitTruth]:
    """``two_feet_walks`` without its first 3 s of standing: both feet swing from the first sample (the
    right a half stride ahead), walk as many strides as fit and stand from then on."""
    left = simulate_walk(path, duration_s, rate_hz, speed_mps, seed=seed, lateral_m=FOOT_SIDE_M, initial_still_s=0.0)
    right = simulate_walk(path, duration_s, rate_hz, speed_mps, seed=seed + 1, lateral_m=-FOOT_SIDE_M,
                          initial_still_s=0.0, half_stride_ahead=True)  # fmt: skip
    return left, right


def _rrd_track(path: Path, foot: str) -> tuple[np.ndarray, np.ndarray]:
    """A foot's track in a recording: its times (ns) and positions (float32, drawn offset), in time order."""
    track = (
        RrdReader(path).stream().collect().reader(index="imu_time", contents=[f"/world/{foot}/track"]).to_arrow_table()
    )
    t_ns = np.asarray(track["imu_time"].cast("int64").to_numpy())
    pos = np.asarray(pc.list_flatten(pc.list_flatten(track[f"/world/{foot}/track:Points3D:positions"])).to_numpy())
    order = np.argsort(t_ns, kind="stable")
    return t_ns[order], pos.reshape(-1, 3)[order]


def test_two_coupled_feet_that_start_in_motion_fill_in_their_lead_ins(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two emulated units walk from their first sample (20 s: about 18 s of strides, then they stand)
    through the real serial path, coupled by the distance bound: each foot's lockstep fills its lead-in
    in at the end of its stream, alone. Each reaches the foot's sinks and the .rrd, equals bit for bit
    ``navigate_every_sample`` on that foot's captured samples alone, and so does each forward track (the
    bound never acted: the feet stand side by side from the alignment on); the summary counts them, and
    a replay of the capture gives them again. (``DemoOptions.initial_still_s`` is one foot's: the
    demo's two-feet walks are swapped for :func:`_walking_from_the_first_sample`.)"""
    monkeypatch.setattr(demo, "two_feet_walks", _walking_from_the_first_sample)
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    got: dict[str, list[NavBatch]] = {}
    rrd = tmp_path / "live.rrd"
    opts = DemoOptions(duration_s=20.0, feet=2, viewer=False, save=rrd, realtime=math.inf, config=cfg,
                       collect=lambda foot: got.setdefault(foot, []).append)  # fmt: skip
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert run_demo(opts) == 0
    assert "feet coupled: 0 corrections" in printed.getvalue()
    (capture,) = tmp_path.glob("*.mcap")
    collected = captured_samples(capture, checked_summary(ReplayOptions(path=capture, config=defaults())), defaults())
    nav_config = demo_config(DemoOptions(config=defaults(), feet=2)).nav_config()
    lead_ins: dict[str, NavBatch] = {}
    for foot in ("left", "right"):
        *forward_batches, lead_in = got[foot]  # the lead-in after the forward batches: the end of the stream
        lead_ins[foot] = lead_in
        forward = concat_batches(forward_batches)
        assert float(lead_in.t_s[-1]) < float(forward.t_s[0]) and len(lead_in) + len(forward) == 20_000
        assert lead_in.step_onsets is not None and lead_in.step_onsets.size > 10  # its steps found
        samples = ImuBatch.concat(collected[foot].batches)
        whole, stats = navigate_every_sample(
            samples.t_s, samples.acc_b_mps2, samples.gyr_b_radps, collected[foot].rate_hz, nav_config
        )
        assert whole is not None and stats.samples_navigated_backwards == len(lead_in) > 17_000
        assert_same(lead_in, _part(whole, 0, len(lead_in)))
        assert_same(forward, _part(whole, len(lead_in), len(whole)))
        assert f"{foot}: lead-in: {len(lead_in)} samples before the first still period navigated backwards" in (
            printed.getvalue()
        )
        t_ns, pos = _rrd_track(rrd, foot)
        assert t_ns.size == 20_000
        np.testing.assert_allclose(t_ns[: len(lead_in)], lead_in.t_s * 1e9, rtol=0, atol=1.0)  # ns
        shown = lead_in.pos_n_m + np.asarray(FOOT_START_OFFSET_M[foot])  # drawn side by side
        np.testing.assert_allclose(pos[: len(lead_in)], shown, rtol=0, atol=2e-6)  # float32 in the recording
    # the replay in process: the same lead-ins
    again: dict[str, list[NavBatch]] = {}
    replay = ReplayOptions(path=capture, config=defaults(), viewer=False,
                           collect=lambda f: again.setdefault(f, []).append)  # fmt: skip
    with contextlib.redirect_stdout(io.StringIO()):
        assert run_replay(replay) == 0
    for foot in ("left", "right"):
        assert_same(again[foot][-1], lead_ins[foot])
