"""ToF, per-stride clearance and barometer entities in a real .rrd, read back: the navigator's output
on an emulated walk with ToF sensors and a barometer, logged in live-sized batches."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import rerun as rr
from footnav.app.experiments import tof as exp
from footnav.app.feet import FOOT_START_OFFSET_M, offset_sink
from footnav.device.emulator.scripts import baro_from_height
from footnav.pipeline.aiding.baro import PressureBatch
from footnav.pipeline.aiding.tof_types import TofConfig
from footnav.pipeline.gait.events import GaitEventTracker
from footnav.pipeline.gait.tof_clearance import swing_clearance
from footnav.pipeline.nav_types import NavBatch, concat_batches
from footnav.pipeline.navigation.navigator import NavConfig, Navigator
from footnav.pipeline.samples import ImuBatch
from footnav.views.logger import RerunLogger
from footnav.views.paths import TIMELINE, FootPaths
from rerun.chunk import RrdReader


def _values(store: object, entity: str) -> tuple[np.ndarray, np.ndarray]:
    tbl = store.reader(index=TIMELINE, contents=[f"/{entity}"]).to_arrow_table()  # type: ignore[attr-defined]
    col = tbl[f"/{entity}:Scalars:scalars"]
    keep = pc.invert(pc.is_null(col))
    t = pc.filter(tbl[TIMELINE], keep).cast("int64").to_numpy() / 1e9
    vals = pc.list_flatten(pc.filter(col, keep)).to_numpy(zero_copy_only=False)
    return t, np.asarray(vals).reshape(len(t), -1)


def test_tof_entities_round_trip_through_an_rrd(tmp_path: Path) -> None:
    rec = exp.record("stairs", 25.0, seed=2)
    t = rec.truth
    baro = baro_from_height(t.t_s, t.pos_n_m[:, 2])
    nav = Navigator(NavConfig(), t.rate_hz)
    nav.add_ranges(rec.ranges)
    nav.add_pressure(PressureBatch(baro.t_s, baro.pressure_pa))
    path = tmp_path / "tof.rrd"
    logger = RerunLogger([rr.FileSink(str(path))], recording_id="tof-views")
    events = GaitEventTracker(TofConfig().snap_m)
    outs = []
    for a in range(0, len(t), 50):
        idx = np.arange(a, min(a + 50, len(t)))
        out = nav.process(
            ImuBatch(t.t_s[idx], rec.acc_b_mps2[idx], rec.gyr_b_radps[idx], idx, np.zeros(idx.size, np.int64))
        )
        if out is not None:
            outs.append(out)
            assert logger.put(events.annotate(out))
    rest = events.finish()
    assert rest is not None
    logger.log_swing_clearance(rest)
    assert logger.close() and logger.stats.error is None
    whole = concat_batches(outs)
    r, strides, alt = whole.ranges, whole.strides, whole.altitude
    assert r is not None and strides is not None and alt is not None and whole.floor_z_m is not None
    store = RrdReader(path).stream().collect()
    p = FootPaths()
    for k in range(3):
        sel = (r.sensor == k) & np.isfinite(r.height_m)
        t_k, h_k = _values(store, p.tof_height(k))
        np.testing.assert_allclose(t_k, r.t_s[sel], atol=1e-6)
        np.testing.assert_allclose(h_k[:, 0], r.height_m[sel], atol=1e-9)
    # the clearance from each swing's hits past and future, every sample once, as over the whole walk
    t_sw, c_sw = _values(store, p.swing_clearance)
    np.testing.assert_allclose(t_sw, whole.t_s, atol=1e-6)
    expected = swing_clearance(whole.t_s, whole.pos_n_m, whole.stance, whole.clearance_m, r, TofConfig().snap_m)
    np.testing.assert_allclose(c_sw[:, 0], expected, atol=1e-9)
    assert np.any(np.abs(expected - whole.clearance_m) > 0.01)  # it differs from the live one at step edges
    t_st, mm = _values(store, p.stride_clearance)
    np.testing.assert_allclose(t_st, strides.t_s, atol=1e-6)
    assert len(strides) >= 15
    np.testing.assert_allclose(mm, np.column_stack([strides.min_m, strides.max_m]), atol=1e-9)
    _, counts = _values(store, p.tof_readings)
    assert counts[-1].sum() == len(r)  # every reading counted once: used + gated + invalid status
    assert counts[-1, 1] > 100  # step edges on the stairs, visible as gated
    # the floor map: one point per reading that met a floor, where it met it; the hits on the
    # floor levels lie on the treads the foot climbed (within 2.3 cm of a true tread: the climb's
    # vertical error, this 25 s walk ending on the landing before the turn that corrects it)
    tbl = store.reader(index=TIMELINE, contents=[f"/{p.floor_hits}"]).to_arrow_table()
    col = tbl[f"/{p.floor_hits}:Points3D:positions"]
    pts = np.asarray(pc.list_flatten(pc.filter(col, pc.invert(pc.is_null(col)))).to_pylist())
    hit = np.isfinite(r.hit_point_n_m[:, 0])
    np.testing.assert_allclose(pts, r.hit_point_n_m[hit], atol=1e-6)
    on_level = r.hit_point_n_m[hit & r.hit_on_level, 2]
    treads = np.unique(np.round(t.floor_z_m, 6))
    assert on_level.size > 500 and np.max(np.min(np.abs(on_level[:, None] - treads[None, :]), axis=1)) < 0.03
    t_alt, h_alt = _values(store, p.altitude)
    np.testing.assert_allclose(h_alt[:, 0], alt.altitude_m, atol=1e-9)
    # the pressure altitude follows the climb (ISA from the emulator's pressure), within 2 cm
    np.testing.assert_allclose(h_alt[:, 0], np.interp(t_alt, t.t_s, t.pos_n_m[:, 2]), atol=0.02)


def test_two_feet_display_offset_moves_the_floor_hits_with_the_track() -> None:
    """footnav.app.feet.offset_sink (two feet drawn side by side): the readings' floor hits are shifted
    with the
    positions, so the views' floor lookups along the way see both in one frame."""
    rec = exp.record("rectangle", 8.0, seed=1)
    t = rec.truth
    nav = Navigator(NavConfig(), t.rate_hz)
    nav.add_ranges(rec.ranges)
    idx = np.arange(len(t))
    out = nav.process(ImuBatch(t.t_s, rec.acc_b_mps2, rec.gyr_b_radps, idx, np.zeros(idx.size, np.int64)))
    assert out is not None and out.ranges is not None and out.floor_z_m is not None
    got: list[NavBatch] = []
    offset_sink(got.append, FOOT_START_OFFSET_M["left"])(out)
    (shifted,) = got
    off = np.asarray(FOOT_START_OFFSET_M["left"])
    assert shifted.ranges is not None and shifted.floor_z_m is not None
    np.testing.assert_allclose(shifted.pos_n_m - out.pos_n_m, np.broadcast_to(off, out.pos_n_m.shape))
    hit = np.isfinite(out.ranges.hit_point_n_m[:, 0])
    assert hit.sum() > 500
    moved = shifted.ranges.hit_point_n_m[hit] - out.ranges.hit_point_n_m[hit]
    np.testing.assert_allclose(moved, np.broadcast_to(off, moved.shape))
    np.testing.assert_allclose(shifted.pos_n_m[:, 2] - shifted.floor_z_m, out.pos_n_m[:, 2] - out.floor_z_m)
