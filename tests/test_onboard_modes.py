"""``footnav live --mode ins|steps``: the unit's own INS states and stepwise dead reckoning, live through
the serial path against emulated units of each model (Oblu on the 2015 command set, MIMU22BT on the
2014 set), captured, replayed alike and read back from the saved ``.rrd``; units at other base rates;
what is refused."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pytest
from footnav.app.commands.live import LiveOptions, live_session
from footnav.app.commands.replay import ReplayOptions, run_replay
from footnav.app.config import defaults
from footnav.device.emulator.motion.gait import GaitTruth, simulate_walk
from footnav.device.emulator.scripts import steps_from_truth, yaw_from_quat_wxyz
from footnav.device.emulator.serving.pty import PtyShoeServer
from footnav.device.emulator.units import emulated_unit, ins_from_truth
from footnav.device.files.capture import read_capture_info, summarize_capture
from footnav.pipeline.errors import FootnavError
from footnav.pipeline.nav_types import NavBatch, concat_batches
from rerun.chunk import RrdReader


@pytest.fixture(scope="module")
def walk() -> GaitTruth:
    return simulate_walk("rectangle", 30.0, rate_hz=1000.0, seed=2)


def run_live(
    server: PtyShoeServer,
    tmp_path: Path,
    enough: Callable[[int], bool],
    settings: dict[str, object] | None = None,
    **opts: object,
) -> list[NavBatch]:
    """A live session on the emulated unit until ``enough(estimates so far)``; its batches."""
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    for key, value in (settings or {}).items():
        cfg.set(key, value, "test")
    got: list[NavBatch] = []

    async def session() -> None:
        options = LiveOptions(
            ports={"foot": server.port}, config=cfg, viewer=False, collect=lambda _f: got.append, **opts
        )  # type: ignore[arg-type]
        task = asyncio.create_task(live_session(options))
        async with asyncio.timeout(120):
            while not enough(sum(len(b) for b in got)) and not task.done():
                await asyncio.sleep(0.1)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task

    asyncio.run(session())
    return got


def replayed(capture: Path, save: Path | None = None) -> NavBatch:
    out: list[NavBatch] = []
    opts = ReplayOptions(path=capture, config=defaults(), viewer=False, save=save, collect=lambda _f: out.append)
    assert run_replay(opts) == 0
    return concat_batches(out)


@pytest.mark.parametrize(("model", "output"), [("mimu22bt", "auto"), ("oblu", "steps")])
def test_stepwise_output_live_captured_replayed_and_saved(
    walk: GaitTruth, tmp_path: Path, model: str, output: str
) -> None:
    """The 2014 MIMU22BT, asked for nothing (its firmware probed, its stepwise output taken), and an Oblu
    asked for ``--mode steps``: every packet applied once, the track and covariance the unit sent."""
    steps = steps_from_truth(walk.t_s, walk.pos_n_m, yaw_from_quat_wxyz(walk.quat_nb_wxyz), walk.stance)
    with emulated_unit(model, walk, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf) as server:
        got = run_live(server, tmp_path, lambda n: n >= len(steps), output=output)
        commands = [c.cmd_id for c in server.commands]
    track = concat_batches(got)
    assert len(track) == len(steps)
    np.testing.assert_allclose(track.pos_n_m, steps.pos_n_m, atol=3e-3)  # float32 steps summed
    assert np.all(np.diff(track.t_s) > 0)
    assert track.cov_pos_yaw is not None and track.cov_pos_yaw[-1, 0, 0] > track.cov_pos_yaw[0, 0, 0] > 0
    assert track.step_onsets is not None and track.step_onsets.size == np.count_nonzero(
        np.linalg.norm(steps.dx_m, axis=1) >= 0.05
    )
    assert (0x14 in commands) == (model == "mimu22bt") and (0x34 in commands) == (model == "oblu")
    capture = next(tmp_path.glob("*.mcap"))
    info = summarize_capture(capture)
    if model == "mimu22bt":  # the header says what was asked; the event what the firmware gave
        assert any(e.get("event") == "mode" and e.get("mode") == "steps" for e in info.events["foot"])
    else:
        assert read_capture_info(capture).units[0].settings["mode"] == "steps"
    rrd = tmp_path / "steps.rrd"
    again = replayed(capture, save=rrd)
    assert len(again) == len(track)
    np.testing.assert_array_equal(again.pos_n_m, track.pos_n_m)
    store = RrdReader(rrd).stream().collect()
    markers = store.reader(index="imu_time", contents=["/world/foot/step_cov"]).to_arrow_table()
    half = pc.list_flatten(markers["/world/foot/step_cov:Ellipsoids3D:half_sizes"])
    assert len(half) == track.step_onsets.size  # a floor ellipse per step


def test_ins_output_live_captured_and_replayed(walk: GaitTruth, tmp_path: Path) -> None:
    """``--mode ins`` on an Oblu: the unit's states with their covariance, at 250 Hz by default, stance
    where the on-board speed is held near zero."""
    with emulated_unit("oblu", walk, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf) as server:
        n = walk.t_s.size // 4
        got = run_live(server, tmp_path, lambda k: k >= n - 10, output="ins")
    track = concat_batches(got)
    k = np.round(track.t_s * 1000.0).astype(int)
    assert len(track) >= n - 10 and np.all(np.diff(k) == 4)  # every 4th sample: 250 Hz
    np.testing.assert_allclose(track.pos_n_m, walk.pos_n_m[k], atol=1e-5)  # float32 on the wire
    np.testing.assert_allclose(track.pos_cov_n_m2, ins_from_truth(walk).cov_9x9[k][:, :3, :3], rtol=1e-5)  # type: ignore[index]
    assert np.array_equal(track.stance, np.linalg.norm(walk.vel_n_mps[k], axis=1) < 0.05)
    capture = next(tmp_path.glob("*.mcap"))
    settings = read_capture_info(capture).units[0].settings
    assert settings["mode"] == "ins" and settings["rate_divider_log2"] == 2
    again = replayed(capture)
    m = min(len(again), len(track))
    np.testing.assert_array_equal(again.pos_n_m[:m], track.pos_n_m[:m])


@pytest.mark.parametrize(
    ("model", "k", "rate_hz"), [("openshoe", 0, 819.2), ("mimu4444", 0, 250.0), ("mimu4444", 3, 31.25)]
)
def test_units_at_other_base_rates_are_asked_and_navigated_at_their_rate(
    tmp_path: Path, model: str, k: int, rate_hz: float
) -> None:
    """An OpenShoe board at 819.2 Hz and a MIMU4444 at 31.25 Hz (K = 3 of its 250 Hz base) named with
    ``--unit``: the rate asked is the rate the clock gives, so nothing is retimed and nothing warned."""
    from footnav.device.models import unit_model

    base = unit_model(model).base_rate_hz
    walk = simulate_walk("line", 20.0, rate_hz=base, seed=4)
    n = walk.t_s.size // 2**k - round(1.5 * rate_hz)  # less the still start before the alignment
    with emulated_unit(model, walk, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf) as server:
        got = run_live(server, tmp_path, lambda m: m >= n, {"unit.rate_divider": k}, model=model)
    track = concat_batches(got)
    assert np.allclose(np.diff(track.t_s), 1.0 / rate_hz, rtol=1e-6)
    settings = read_capture_info(next(tmp_path.glob("*.mcap"))).units[0].settings
    assert settings["rate_hz"] == rate_hz and settings["model"] == model
    error_m = np.linalg.norm(track.pos_n_m[-1] - walk.pos_n_m[round(float(track.t_s[-1]) * base)])
    assert error_m < 0.05 * walk.distance_m


@pytest.mark.parametrize(
    ("opts", "message"),
    [
        ({"model": "mimu22bt", "output": "ins"}, r"MIMU22BT \(2014 firmware\) streams steps, not --mode ins"),
        ({"model": "openshoe", "output": "raw"}, r"OpenShoe \(ADIS16367\) streams imu, ins, steps, not --mode raw"),
        ({"output": "steps", "tof": True}, r"--mode steps shows the unit's own solution: drop --dual-imu and --tof"),
        ({"output": "ins", "dual_imu_lever_b_m": (0.01, 0.0, 0.0)}, r"--mode ins shows the unit's own solution"),
    ],
)  # fmt: skip
async def test_what_a_unit_cannot_stream_is_refused_before_anything_opens(
    tmp_path: Path, opts: dict[str, object], message: str
) -> None:
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path), "test")
    live = LiveOptions(ports={"foot": str(tmp_path / "none")}, config=cfg, viewer=False, **opts)  # type: ignore[arg-type]
    with pytest.raises(FootnavError, match=message):
        await live_session(live)
    assert not list(tmp_path.glob("*.mcap"))


@pytest.mark.parametrize("asked", ["imu", "steps"])
async def test_a_2014_unit_is_resumed_with_its_own_stepwise_start_after_a_replug(
    walk: GaitTruth, tmp_path: Path, asked: str
) -> None:
    """What the link re-sends after a reconnect is learned in the unit's command set: the 2014 SWDR
    start (14 00 14), not the 2015 probes (40 .., 34 ..) that the 2014 parser would misread, and no
    watchdog on the stepwise stream's pauses."""
    import os

    from footnav.device.links.reconnecting import ReconnectingLink
    from footnav.device.modes import NormalImuMode, StepwiseMode
    from footnav.device.protocol.commands import Commands2014
    from footnav.device.protocol.stepwise import StepBatch
    from footnav.device.unit import OpenShoeUnit

    port = tmp_path / "ttyMIMU"
    first = emulated_unit("mimu22bt", walk, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf)
    second = emulated_unit("mimu22bt", walk, walk.acc_b_mps2, walk.gyr_b_radps, speed=math.inf)
    with first, second:
        os.symlink(first.port, port)
        link = ReconnectingLink.serial(str(port))
        await link.open()
        unit = OpenShoeUnit(link)
        if asked == "imu":  # refused, then the stepwise output (live --mode auto)
            with pytest.raises(FootnavError, match="2014"):
                await unit.start(NormalImuMode())
        await unit.start(StepwiseMode())  # asked at once, its 2014 start is the answered probe
        assert link.resume_bytes == Commands2014().stepwise_dead_reckoning().frame
        first.unplug()
        os.replace(port, tmp_path / "gone")
        os.symlink(second.port, port)
        got = 0
        async with asyncio.timeout(30):
            async for batch in unit.batches():
                got += len(batch) if isinstance(batch, StepBatch) else 0
                if got >= 3 and second.commands:
                    break
        await unit.close()
    assert [c.cmd_id for c in second.commands if c.cmd_id != 0x01][:1] == [0x14]
    assert link.health.reconnects == 1 and link.health.stalls == 0


@pytest.mark.parametrize(
    ("model", "mode", "shown"),
    [
        ("mimu22bt", "auto", "stepwise packets"),
        ("oblu", "ins", "estimates"),
        ("mimu22bl", "raw", "estimates"),
        ("OpenShoe", "auto", "estimates"),  # any case; an ADIS16367 emulated and navigated with its profile
    ],
)
def test_demo_runs_live_against_an_emulated_unit_of_the_model(
    tmp_path: Path, model: str, mode: str, shown: str
) -> None:
    """``footnav demo --unit MODEL --mode MODE``: the live session on the emulated unit, its recording
    and capture, and the final error against the emulator's truth."""
    import subprocess
    import sys

    rrd = tmp_path / "u.rrd"
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "demo", "--unit", model, "--mode", mode, "--duration", "20",
         "--pace", "max", "--no-viewer", "--save", str(rrd), "--sessions", str(tmp_path)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert f"{shown} received" in proc.stdout and "final position error: 0.0" in proc.stdout, proc.stdout
    # the unit's own solution is the emulator's truth: its error says nothing of footnav's navigation
    assert ("checks the decoding" in proc.stdout) == (mode == "ins" or model == "mimu22bt"), proc.stdout
    from rerun.error_utils import RerunWarning

    with pytest.warns(RerunWarning, match="no footer"):  # a live session's recording keeps no footer index
        store = RrdReader(rrd).stream().collect()
    steps = store.reader(index="imu_time", contents=["/world/foot/steps"]).to_arrow_table()
    assert steps.num_rows > 5
    capture = next(tmp_path.glob("*.mcap"))
    settings = read_capture_info(capture).units[0].settings
    assert settings["model"] == model.lower()
    auto = "normal_imu" if model == "OpenShoe" else "steps"
    assert settings["mode"] == {"auto": auto, "ins": "ins", "raw": "raw_imu_fused"}[mode]
    imu = "adis16367" if model == "OpenShoe" else "mpu6500x4"
    assert settings["nav_config"]["profile"]["name"] == imu and f"command set, {imu})" in proc.stderr
    export = subprocess.run(
        [sys.executable, "-m", "footnav.app", "export", str(capture), "-o", str(tmp_path / "t.csv"),
         "--steps", str(tmp_path / "s.csv")],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    if settings["mode"] == "steps":  # the unit's own steps: none to find in a walk (and no empty file)
        assert export.returncode == 2 and "holds the unit's own steps" in export.stderr, export.stderr
        assert not (tmp_path / "s.csv").exists()
        return
    assert export.returncode == 0 and "Traceback" not in export.stderr, export.stderr


def test_demo_asks_the_emulated_unit_for_a_rate_divider_and_imu_mask(tmp_path: Path) -> None:
    """``demo --unit`` takes ``live``'s ``--rate-divider`` and ``--imu-mask`` (and refuses them without it)."""
    import subprocess
    import sys

    def demo(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "footnav.app", "demo", *args, "--duration", "8", "--pace", "max",
             "--no-viewer", "--sessions", str(tmp_path)],
            capture_output=True, text=True, timeout=300, check=False,
        )  # fmt: skip

    proc = demo("--unit", "mimu22bl", "--mode", "raw", "--imu-mask", "0x3", "--rate-divider", "1")
    assert proc.returncode == 0, proc.stderr
    settings = read_capture_info(next(tmp_path.glob("*.mcap"))).units[0].settings
    assert settings["fused_imu_mask"] == 0x3 and settings["rate_divider_log2"] == 1
    assert "4000 estimates received" in proc.stdout  # 8 s at 500 Hz
    config = tmp_path / "footnav.toml"
    config.write_text("[unit]\nrate_divider = 2\n")  # for live sessions; the built-in demo is not asked
    assert demo("--config", str(config)).returncode == 0
    for args, said in (
        (("--rate-divider", "1"), "need --unit MODEL"),
        (("--unit", "oblu", "--imu-mask", "3"), "--imu-mask applies to --mode raw"),
    ):
        proc = demo(*args)
        assert proc.returncode == 2 and said in proc.stderr, proc.stderr
