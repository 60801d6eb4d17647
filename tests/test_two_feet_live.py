"""Two feet coupled as their samples stream in (``footnav.pipeline.two_feet.live``): the lockstep gives
``navigate_feet``'s estimates bit for bit whatever the order and size of the two feet's batches, finds
the feet's clock offset from their host times, fills each foot's lead-in in on its own, and lets a
foot go on alone when the other stops; the demo's two emulated units through the real serial path are
coupled by it (the recording holds the coupled tracks, a replay repeats them), independent feet are
each foot's own navigation, and ``export --left --right`` writes ``navigate_pair``'s two tracks."""

from __future__ import annotations

import contextlib
import io
import math
import re
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from footnav.app.api.feet import navigate_pair
from footnav.app.cli import main
from footnav.app.commands.demo import DemoOptions, run_demo
from footnav.app.commands.replay import ReplayOptions, checked_summary, run_replay
from footnav.app.commands.smooth_capture import captured_samples
from footnav.app.config import Config, defaults
from footnav.app.feet import FOOT_START_OFFSET_M
from footnav.device.emulator.motion.gait import simulate_walk, two_feet_walks
from footnav.device.emulator.sensors.imu_errors import IMU_GRADES, corrupt
from footnav.device.files.capture import read_capture_info
from footnav.device.files.recordings import load_recording
from footnav.pipeline.nav_types import NavBatch, concat_batches
from footnav.pipeline.navigation.lead_in import navigate_every_sample
from footnav.pipeline.navigation.navigator import NavConfig, Navigator
from footnav.pipeline.samples import ImuBatch
from footnav.pipeline.smoothing.stepwise import StepSmoothingNavigator
from footnav.pipeline.two_feet import FootSeparation, FootSignals, navigate_feet
from footnav.pipeline.two_feet.heading import RelativeHeading
from footnav.pipeline.two_feet.live import FeetLockstep, coupling_refusal


@pytest.fixture(scope="module")
def figure8() -> tuple[FootSignals, FootSignals]:
    """30 s of the figure eight, seed 2, with the datasheet's axis errors: the bound acts 8 times."""
    out = []
    for i, tr in enumerate(two_feet_walks("figure8", 30.0, seed=2)):
        acc, gyr, _ = corrupt(
            tr.acc_b_mps2, tr.gyr_b_radps, tr.rate_hz, IMU_GRADES["mpu6500x4"], seed=2 + i, axes="gyro-bias-calibrated"
        )
        out.append(FootSignals(tr.t_s, acc, gyr, tr.rate_hz))
    return out[0], out[1]


def _stream(
    lockstep: FeetLockstep,
    feet: tuple[FootSignals, FootSignals],
    rng: np.random.Generator,
    host0_ns: tuple[int, int] = (0, 0),
    t_shift_s: tuple[float, float] = (0.0, 0.0),
    stop_after: tuple[float, float] = (np.inf, np.inf),
    counting: Sequence[Callable[[NavBatch], object]] = (),
    max_batch: int = 120,
) -> list[list[NavBatch]]:
    """Feed both feet's samples in random batches (1-``max_batch`` samples) in a random interleaving, each foot's
    time on its own session clock (``t_shift_s`` subtracted) and its host stamps from ``host0_ns`` on;
    a foot stops (and is ended) after ``stop_after`` seconds. Returns what each foot's sinks got
    (``counting``: one more sink per foot)."""
    got: list[list[NavBatch]] = [[], []]
    cursors = [0, 0]
    batches = [sig.batch() for sig in feet]
    for i in (0, 1):
        lockstep.port(i).bind_sinks([got[i].append, *counting[i : i + 1]])
    ends = [int(np.searchsorted(sig.t_s, sig.t_s[0] + stop)) if np.isfinite(stop) else len(sig.t_s)
            for sig, stop in zip(feet, stop_after, strict=True)]  # fmt: skip
    while any(cursors[i] < ends[i] for i in (0, 1)):
        i = int(rng.integers(2))
        if cursors[i] >= ends[i]:
            i = 1 - i
        a = cursors[i]
        b = min(ends[i], a + int(rng.integers(max_batch // 4 + 1, max_batch + 1)))
        part = batches[i].select(slice(a, b))
        host = host0_ns[i] + np.round(part.t_s * 1e9).astype(np.int64)
        t = part.t_s - t_shift_s[i]
        lockstep.port(i).process(ImuBatch(t, part.acc_b_mps2, part.gyr_b_radps, part.counter, host))
        cursors[i] = b
        if b >= ends[i]:
            lockstep.end(i)
    return got


@pytest.mark.parametrize(("heading", "max_batch"), [(False, 120), (True, 120), (False, 1000), (True, 1000)])
def test_any_interleaving_is_navigate_feet_bit_for_bit(
    figure8: tuple[FootSignals, FootSignals], heading: bool, max_batch: int
) -> None:
    """Batches of up to 120 samples (a live read) and up to 1 s (a replay's, where the lockstep leaps
    over the cells in which the feet stay inside the bound, and undoes a leap that comes near it)."""
    bound = FootSeparation(heading=RelativeHeading() if heading else None)
    ref = navigate_feet(figure8[0], figure8[1], coupling=bound)
    assert len(ref.heading_updates if heading else ref.corrections) > 3  # the heading keeps them within R
    for seed in (1, 2):
        lock = FeetLockstep(Navigator(NavConfig(), 1000.0), Navigator(NavConfig(), 1000.0), bound, clock="shared")
        got = _stream(lock, figure8, np.random.default_rng(seed), max_batch=max_batch)
        assert lock.drained(0) and lock.drained(1)
        for est, want in zip(got, (ref.left, ref.right), strict=True):
            assert want is not None
            track = concat_batches(est)
            np.testing.assert_array_equal(track.t_s, want.t_s)
            np.testing.assert_array_equal(track.pos_n_m, want.pos_n_m)
            np.testing.assert_array_equal(track.quat_nb_wxyz, want.quat_nb_wxyz)
        assert lock.corrections == ref.corrections[: len(lock.corrections)]
        assert len(lock.corrections) == len(ref.corrections)
        np.testing.assert_array_equal(lock.distance_before_m, ref.distance_before_m)
        if max_batch > 120:
            assert lock.leaped_cells > 100 and lock.undone_leaps > 0
        if heading:
            assert lock.heading is not None and lock.heading.times_s == ref.heading_updates


def test_host_times_put_session_clocks_on_one_grid(figure8: tuple[FootSignals, FootSignals]) -> None:
    """Each unit's session clock starts at its own first sample: the right foot's stream starts 0.3 s
    late on the host, so its session time is 0.3 s behind; matched by host time the result is the
    lockstep on the shared clock (to rounding), with every time stamp the foot's own."""
    bound = FootSeparation(heading=None)  # the bound alone: it acts on this walk
    shared = FeetLockstep(Navigator(NavConfig(), 1000.0), Navigator(NavConfig(), 1000.0), bound, clock="shared")
    want = _stream(shared, figure8, np.random.default_rng(3))
    late = 0.3
    cut = round(late * 1000)
    right = FootSignals(
        figure8[1].t_s[cut:], figure8[1].acc_b_mps2[cut:], figure8[1].gyr_b_radps[cut:], figure8[1].rate_hz
    )
    ref = navigate_feet(figure8[0], right, coupling=bound)
    host = FeetLockstep(Navigator(NavConfig(), 1000.0), Navigator(NavConfig(), 1000.0), bound, clock="host")
    got = _stream(host, (figure8[0], right), np.random.default_rng(4), host0_ns=(5_000_000_000, 5_000_000_000),
                  t_shift_s=(0.0, float(right.t_s[0])))  # fmt: skip
    assert len(host.corrections) == len(ref.corrections) > 3 and want
    for est, expect, shift in zip(got, (ref.left, ref.right), (0.0, float(right.t_s[0])), strict=True):
        assert expect is not None
        track = concat_batches(est)
        np.testing.assert_allclose(track.t_s, expect.t_s - shift, rtol=0, atol=1e-9)
        # the foot's own time stamps (t − 0.3 s) round its sample intervals differently: 1e-14 m apart
        np.testing.assert_allclose(track.pos_n_m, expect.pos_n_m, rtol=0, atol=1e-9)


def test_a_stopped_foot_holds_the_other_back_only_max_lead(figure8: tuple[FootSignals, FootSignals]) -> None:
    lock = FeetLockstep(
        Navigator(NavConfig(), 1000.0), Navigator(NavConfig(), 1000.0), FootSeparation(), clock="shared", max_lead_s=0.5
    )
    got: list[list[NavBatch]] = [[], []]
    for i in (0, 1):
        lock.port(i).bind_sinks([got[i].append])
    left, right = (sig.batch() for sig in figure8)
    for a in range(0, 5400, 40):  # the right foot's link stalls after 5 s
        lock.port(0).process(left.select(slice(a, a + 40)))
        if a < 5000:
            lock.port(1).process(right.select(slice(a, min(a + 40, 5000))))
    # 5.4 s of the left foot received, held at the right foot's last cell (up to 4.95 s) while it is
    # less than 0.5 s ahead
    assert concat_batches(got[0]).t_s[-1] == pytest.approx(4.949) and lock.released_cells == 0
    for a in range(5400, 12000, 40):
        lock.port(0).process(left.select(slice(a, a + 40)))
    # then it goes on alone, to its last complete cell
    assert concat_batches(got[0]).t_s[-1] == pytest.approx(11.95, abs=1.5e-3)  # edges: t0 + 0.05 k, rounded
    assert lock.released_cells == round((11.95 - 4.95) / 0.05)  # from the cell the right foot did not finish
    lock.port(1).process(right.select(slice(5000, 12000)))  # back: its late samples navigated alone
    assert concat_batches(got[1]).t_s[-1] >= 11.45
    assert not lock.drained(0)
    lock.end(0)
    lock.end(1)
    assert lock.drained(0) and lock.drained(1)
    assert concat_batches(got[0]).t_s[-1] == pytest.approx(11.999)


@pytest.fixture(scope="module")
def walk_then_figure8() -> tuple[FootSignals, FootSignals]:
    """Each foot walks 6 strides of the rectangle from its first sample and rests (9 s), then the figure
    eight of :func:`figure8` (its 3 s of standing first): the first still period, 5.5 s, lies between
    the two walks (the foot stands level at rest, so the body-frame signals join)."""
    out = []
    for i, tr in enumerate(two_feet_walks("figure8", 30.0, seed=2)):
        first = simulate_walk("rectangle", 9.0, seed=7 + i, initial_still_s=0.0, max_strides=6)
        acc, gyr, _ = corrupt(
            np.vstack([first.acc_b_mps2, tr.acc_b_mps2]),
            np.vstack([first.gyr_b_radps, tr.gyr_b_radps]),
            tr.rate_hz,
            IMU_GRADES["mpu6500x4"],
            seed=2 + i,
            axes="gyro-bias-calibrated",
        )
        out.append(FootSignals(np.arange(acc.shape[0]) / tr.rate_hz, acc, gyr, tr.rate_hz))
    return out[0], out[1]


def test_each_coupled_foot_fills_its_lead_in_in_on_its_own(walk_then_figure8: tuple[FootSignals, FootSignals]) -> None:
    """Both feet start in motion: each foot's lead-in (its 6 strides) is filled in once its still
    period has ended, mid-stream, equal bit for bit to ``navigate_every_sample`` on that foot's samples
    alone (the lead-in is not coupled, and it meets the forward track at its first sample, which no
    correction has touched); the forward estimates stay ``navigate_feet``'s bit for bit, which equal the
    uncoupled run's up to the bound's first correction and differ after it."""
    bound = FootSeparation(heading=None)
    ref = navigate_feet(walk_then_figure8[0], walk_then_figure8[1], coupling=bound)
    lock = FeetLockstep(Navigator(NavConfig(), 1000.0), Navigator(NavConfig(), 1000.0), bound, clock="shared")
    lead_ins: list[list[tuple[int, NavBatch]]] = [[], []]
    forward_given = [0, 0]

    def lead_in_sink(i: int) -> Callable[[NavBatch], None]:
        return lambda nav: lead_ins[i].append((forward_given[i], nav))

    lock.port(0).process(walk_then_figure8[0].batch().select(slice(0, 5)))
    with pytest.raises(RuntimeError, match="only from its first batch"):  # it would miss what came
        lock.port(0).fill_lead_in(lead_in_sink(0))
    lock = FeetLockstep(Navigator(NavConfig(), 1000.0), Navigator(NavConfig(), 1000.0), bound, clock="shared")
    for i in (0, 1):
        lock.port(i).fill_lead_in(lead_in_sink(i))
    counted = [lambda nav, i=i: forward_given.__setitem__(i, forward_given[i] + len(nav)) for i in (0, 1)]
    got = _stream(lock, walk_then_figure8, np.random.default_rng(5), counting=counted)
    assert len(ref.corrections) > 3 and lock.corrections == ref.corrections
    first = ref.corrections[0]
    for i, (sig, want) in enumerate(zip(walk_then_figure8, (ref.left, ref.right), strict=True)):
        assert want is not None
        track = concat_batches(got[i])
        for name in ("t_s", "pos_n_m", "vel_n_mps", "quat_nb_wxyz", "pos_cov_n_m2"):
            np.testing.assert_array_equal(getattr(track, name), getattr(want, name), name)
        whole, stats = navigate_every_sample(sig.t_s, sig.acc_b_mps2, sig.gyr_b_radps, sig.rate_hz, NavConfig())
        assert whole is not None
        s = stats.samples_before_alignment
        ((given, lead_in),) = lead_ins[i]
        assert len(lead_in) == s == lock.port(i).stats.samples_navigated_backwards > 5000
        assert 0 < given < len(track)  # mid-stream, once the still period had ended
        for name in ("t_s", "pos_n_m", "vel_n_mps", "quat_nb_wxyz", "pos_cov_n_m2", "cov_pos_yaw", "stance"):
            np.testing.assert_array_equal(getattr(lead_in, name), getattr(whole, name)[:s], name)
        before = track.t_s < first  # the estimates the first correction came after
        assert 1000 < before.sum() < len(track)
        np.testing.assert_array_equal(track.pos_n_m[before], whole.pos_n_m[s:][before])
        assert not np.array_equal(track.pos_n_m[~before], whole.pos_n_m[s:][~before])


def test_only_two_single_imu_navigators_are_coupled() -> None:
    nav = Navigator(NavConfig(), 1000.0)
    assert coupling_refusal([nav, Navigator(NavConfig(), 1000.0)]) is None
    assert coupling_refusal([nav]) == "one foot"
    refusal = coupling_refusal([nav, StepSmoothingNavigator(NavConfig(), 1000.0)])
    assert refusal is not None and "step-smoothing" in refusal


# ---- sessions: the demo's two emulated units on pseudo-terminals, the real serial path ----------------


def _demo(tmp: Path, coupling: str, save: Path | None = None) -> tuple[Path, dict[str, NavBatch], str]:
    """30 s of the figure eight (seed 2, axis errors) on two emulated units at full pace: the capture,
    each foot's estimates in time order, and what the demo printed."""
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp), "test")
    got: dict[str, list[NavBatch]] = {}
    opts = DemoOptions(path="figure8", duration_s=30.0, seed=2, axes="gyro-bias-calibrated", feet=2, viewer=False,
                       realtime=math.inf, save=save, config=cfg, feet_coupling=coupling,
                       collect=lambda foot: got.setdefault(foot, []).append)  # fmt: skip
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert run_demo(opts) == 0
    (capture,) = tmp.glob("*.mcap")
    tracks = {foot: concat_batches(sorted(b, key=lambda n: float(n.t_s[0]))) for foot, b in got.items()}
    return capture, tracks, out.getvalue()


def _samples(capture: Path) -> tuple[Config, dict[str, ImuBatch], dict[str, float]]:
    """Each foot's samples as the replay decodes them from the capture, and the rate its clock gave."""
    cfg = defaults()
    collected = captured_samples(capture, checked_summary(ReplayOptions(path=capture, config=cfg)), cfg)
    return (
        cfg,
        {foot: ImuBatch.concat(c.batches) for foot, c in collected.items()},
        {foot: c.rate_hz for foot, c in collected.items()},
    )


@pytest.fixture(scope="module")
def coupled_demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, NavBatch], str, Path]:
    tmp = tmp_path_factory.mktemp("coupled")
    capture, tracks, printed = _demo(tmp, "distance", save=tmp / "coupled.rrd")
    return capture, tracks, printed, tmp / "coupled.rrd"


def _corrections(printed: str) -> int:
    m = re.search(r"feet coupled: (\d+) corrections of the distance bound", printed)
    assert m, printed
    return int(m[1])


def test_demo_couples_the_feet_as_the_lockstep_does(coupled_demo: tuple[Path, dict[str, NavBatch], str, Path]) -> None:
    """The live session's coupled tracks are the lockstep's on the samples it received (host-time
    matched), bit for bit, however the two units' reads interleaved; the bound acted."""
    capture, live, printed, _ = coupled_demo
    assert read_capture_info(capture).session["feet_coupling"] == "distance"
    cfg, samples, rates = _samples(capture)
    navs = [Navigator(cfg.nav_config(), rates[f]) for f in ("left", "right")]
    lock = FeetLockstep(navs[0], navs[1], FootSeparation(heading=None))  # the demo's "distance"
    got: list[list[NavBatch]] = [[], []]
    for i, foot in enumerate(("left", "right")):
        lock.port(i).bind_sinks([got[i].append])
        lock.port(i).process(samples[foot])
    lock.end(0)
    lock.end(1)
    assert _corrections(printed) == len(lock.corrections) > 0
    for i, foot in enumerate(("left", "right")):
        assert len(live[foot]) == 30_000
        for name in ("t_s", "pos_n_m", "vel_n_mps", "quat_nb_wxyz", "pos_cov_n_m2", "host_ns"):
            np.testing.assert_array_equal(getattr(live[foot], name), getattr(concat_batches(got[i]), name), name)


def test_recording_holds_the_coupled_tracks(coupled_demo: tuple[Path, dict[str, NavBatch], str, Path]) -> None:
    from rerun.chunk import RrdReader

    _, live, _, rrd = coupled_demo
    store = RrdReader(rrd).stream().collect()
    for foot in ("left", "right"):
        tbl = store.reader(index="imu_time", contents=[f"/world/{foot}/track"]).to_arrow_table()
        col = tbl[f"/world/{foot}/track:Points3D:positions"]
        pos = np.asarray(pc.list_flatten(pc.list_flatten(col)).to_numpy(zero_copy_only=False)).reshape(-1, 3)
        shown = live[foot].pos_n_m + np.asarray(FOOT_START_OFFSET_M[foot])  # drawn side by side
        assert pos.shape == shown.shape
        np.testing.assert_allclose(pos, shown, rtol=0, atol=2e-6)  # float32 in the recording


def test_replay_couples_the_feet_as_the_session_did(coupled_demo: tuple[Path, dict[str, NavBatch], str, Path]) -> None:
    capture, live, printed, _ = coupled_demo
    got: dict[str, list[NavBatch]] = {}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        opts = ReplayOptions(path=capture, config=defaults(), viewer=False,
                             collect=lambda foot: got.setdefault(foot, []).append)  # fmt: skip
        assert run_replay(opts) == 0
    assert _corrections(out.getvalue()) == _corrections(printed)
    for foot in ("left", "right"):
        again = concat_batches(got[foot])
        np.testing.assert_array_equal(again.pos_n_m, live[foot].pos_n_m)
        np.testing.assert_array_equal(again.host_ns, live[foot].host_ns)


def test_independent_feet_are_each_foots_own_navigation(
    tmp_path: Path, coupled_demo: tuple[Path, dict[str, NavBatch], str, Path]
) -> None:
    capture, live, printed = _demo(tmp_path, "independent")
    assert "feet coupled" not in printed and "feet independent: each foot navigated on its own" in printed
    cfg, samples, rates = _samples(capture)
    for foot in ("left", "right"):
        alone = Navigator(cfg.nav_config(), rates[foot]).process(samples[foot])
        assert alone is not None and len(live[foot]) == 30_000
        np.testing.assert_array_equal(live[foot].pos_n_m, alone.pos_n_m)
        np.testing.assert_array_equal(live[foot].quat_nb_wxyz, alone.quat_nb_wxyz)
    # the same walk coupled ends elsewhere: the bound moved the tracks
    coupled = coupled_demo[1]
    moved = [float(np.abs(coupled[f].pos_n_m[-1] - live[f].pos_n_m[-1]).max()) for f in ("left", "right")]
    assert max(moved) > 0.05, moved


def _write_csv(path: Path, t_s: np.ndarray, acc: np.ndarray, gyr: np.ndarray) -> None:
    np.savetxt(path, np.column_stack([1000.0 + t_s, acc, gyr]), fmt="%.10g", delimiter=",",
               header="t,ax,ay,az,gx,gy,gz", comments="")  # fmt: skip


@pytest.mark.parametrize("coupling", ["coupled", "independent"])
def test_export_of_a_pair_writes_navigate_pairs_tracks(
    tmp_path: Path, figure8: tuple[FootSignals, FootSignals], coupling: str
) -> None:
    paths = tmp_path / "l.csv", tmp_path / "r.csv"
    for path, sig in zip(paths, figure8, strict=True):
        _write_csv(path, sig.t_s, sig.acc_b_mps2, sig.gyr_b_radps)
    flags = ["--independent-feet"] if coupling == "independent" else []
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = main(["export", "--left", str(paths[0]), "--right", str(paths[1]), "-o", str(tmp_path / "t.parquet"),
                     *flags])  # fmt: skip
    assert code == 0
    ref = navigate_pair(load_recording(paths[0]), load_recording(paths[1]), coupled=coupling == "coupled")
    assert (len(ref.heading_updates) > 0) == (coupling == "coupled")
    assert ("independent" in out.getvalue()) == (coupling == "independent")
    for foot, nav in (("left", ref.left), ("right", ref.right)):
        assert nav is not None
        table: pa.Table = pq.read_table(tmp_path / f"t-{foot}.parquet")
        np.testing.assert_array_equal(table["t"].to_numpy(), nav.t_s)
        written = np.column_stack([table[c].to_numpy() for c in ("x", "y", "z")])
        np.testing.assert_array_equal(written, nav.pos_n_m)


def test_export_refuses_half_a_pair(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", "--left", "a.csv", "-o", str(tmp_path / "t.csv")]) != 0
    assert "--left FILE --right FILE" in capsys.readouterr().err


def test_the_feet_flags_are_refused_where_there_is_no_pair(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--independent-feet`` on a one-foot capture's replay, and on an export without ``--left``/``--right``:
    refused with a message that says what they are for (before: the replay ignored it, the export
    talked of "other inputs")."""
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    opts = DemoOptions(duration_s=5.0, viewer=False, realtime=math.inf, config=cfg)
    with contextlib.redirect_stdout(io.StringIO()):
        assert run_demo(opts) == 0
    (capture,) = tmp_path.glob("*.mcap")
    capsys.readouterr()
    assert main(["replay", str(capture), "--no-viewer", "--independent-feet"]) == 2
    assert f"are for two feet; {capture} holds one" in capsys.readouterr().err
    assert main(["export", str(capture), "-o", str(tmp_path / "t.csv"), "--independent-feet"]) == 2
    assert "are for --left FILE --right FILE" in capsys.readouterr().err
    assert not (tmp_path / "t.csv").exists()
