"""``footnav calibrate`` end to end: the emulated miscalibrated unit on a pty (real serial code) turns
through the icosahedron; the calibration file keyed by its MCU id; the procedure's capture refits the
same; a capture that is not a calibration capture is refused."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from footnav.app.calibration_store import ENV_DIR, calibration_dir, load_calibration
from footnav.app.cli import main
from footnav.app.commands.calibrate import DEMO_MCU_ID, CalibrateOptions, run_calibrate
from footnav.app.config import CLI, Config, defaults
from footnav.device.emulator.sensors.icosahedron import Miscalibration
from footnav.device.files.capture import CaptureWriter, UnitHeader
from footnav.pipeline.calibration.model import TOLERANCE


def _config(tmp_path: Path) -> Config:
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp_path / "sessions"), CLI)
    cfg.set("calibration.dir", str(tmp_path / "cal"), CLI)
    return cfg


def test_demo_procedure_over_the_pty_saves_the_units_calibration_and_its_capture_refits_it(tmp_path: Path) -> None:
    cfg = _config(tmp_path)
    out = io.StringIO()
    code = run_calibrate(CalibrateOptions(config=cfg, demo=True, demo_pace=math.inf, out=out))
    text = out.getvalue()
    assert code == 0, text
    assert f"MCU id {DEMO_MCU_ID.hex()}" in text
    assert "face 1 captured" in text and "calibration determined from" in text
    stored = load_calibration(tmp_path / "cal", DEMO_MCU_ID)
    assert stored is not None
    cal = stored.calibration
    truth = Miscalibration()
    err = cal.theta - truth.theta_at(cal.t_ref_c)
    assert np.abs(err[0:3]).max() < TOLERANCE["scale"]
    assert np.abs(err[3:6]).max() < TOLERANCE["misalignment_rad"]
    assert np.abs(err[6:9]).max() < TOLERANCE["acc_bias_mps2"]
    assert np.abs(cal.gyr_bias_radps - truth.gyr_bias_at(cal.t_ref_c)).max() < TOLERANCE["gyr_bias_radps"]
    doc = json.loads(stored.path.read_text())
    assert doc["mcu_id"] == DEMO_MCU_ID.hex() and doc["calibration"]["model_version"] == 1
    assert len(doc["calibration"]["theta_sigma"]) == 15 and doc["calibration"]["residual_rms_mps2"] > 0

    captures = sorted((tmp_path / "sessions").glob("calibrate-*.mcap"))
    assert len(captures) == 1
    again = io.StringIO()
    cfg2 = _config(tmp_path)
    cfg2.set("calibration.dir", str(tmp_path / "cal2"), CLI)
    assert run_calibrate(CalibrateOptions(config=cfg2, capture_file=captures[0], out=again)) == 0
    assert "residual RMS per face, mm/s²:" in text
    # a calibration capture is not a walk: replay says how to use it
    assert main(["replay", str(captures[0]), "--no-viewer"]) == 2
    refit = load_calibration(tmp_path / "cal2", DEMO_MCU_ID)
    assert refit is not None
    np.testing.assert_array_equal(refit.calibration.theta, cal.theta)


def test_an_undetermined_fit_is_refused_and_nothing_saved(tmp_path: Path) -> None:
    """At 125 Hz (decimated raw output) 2 s holds give an eighth of the samples: 20 faces do not determine
    the fit to the targets, and the procedure says so instead of saving a calibration."""
    out = io.StringIO()
    opts = CalibrateOptions(
        config=_config(tmp_path), demo=True, demo_pace=math.inf, rate_divider_log2=3, hold_s=2.0, out=out
    )
    assert run_calibrate(opts) == 2
    assert "[20/20 faces] the fit is not well determined yet" in out.getvalue()
    assert "capture more faces, each still for longer" in out.getvalue()
    assert not (tmp_path / "cal").exists()


def test_a_non_calibration_capture_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "live.mcap"
    with CaptureWriter(path) as w:
        tap = w.add_unit(UnitHeader("foot", "normal IMU", "2015", "serial", "/dev/x", settings={"mode": "normal_imu"}))
        tap("rx", 1, b"\xa0\x40\x00\xe0")
    assert main(["calibrate", "--capture", str(path), "--no-capture"]) == 2
    assert "not a calibration capture" in capsys.readouterr().err


def test_calibration_folder_from_config_env_xdg(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = defaults()
    monkeypatch.delenv(ENV_DIR, raising=False)
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert calibration_dir(cfg) == tmp_path / "xdg" / "footnav" / "calibration"
    monkeypatch.setenv(ENV_DIR, str(tmp_path / "env"))
    assert calibration_dir(cfg) == tmp_path / "env"
    cfg.set("calibration.dir", str(tmp_path / "cfg"), CLI)
    assert calibration_dir(cfg) == tmp_path / "cfg"


async def test_over_ble_the_procedure_runs_at_125_hz_and_too_few_faces_are_refused(tmp_path: Path) -> None:
    """The emulated unit as a BLE GATT peripheral on bumble's virtual radio, reached through bleak: the
    MCU id, raw output with temperature at the BLE default of 125 Hz, three faces captured, then the
    unit has nothing more to send and the fit refuses with what to redo."""
    from bumble.link import LocalLink
    from footnav.app.commands.calibrate import calibrate_session
    from footnav.app.session import UnitAddress
    from footnav.device.emulator.sensors.icosahedron import miscalibrated_signals, simulate_icosahedron, warm_up_c
    from footnav.device.emulator.serving.ble_backend import BumbleAdapter, bumble_backend
    from footnav.device.emulator.serving.ble_peripheral import BleShoePeripheral
    from footnav.pipeline.calibration.model import TooFewFacesError

    truth = simulate_icosahedron(1000.0, n_faces=3)
    temp = warm_up_c(truth.t_s)
    acc, gyr = miscalibrated_signals(truth.acc_b_mps2, truth.gyr_b_radps, temp, 1000.0)
    link = LocalLink()
    adapter = BumbleAdapter(link)
    unit = BleShoePeripheral(
        link, truth.t_s, acc, gyr, name="FOOT-CAL", speed=math.inf, temp_c=temp, mcu_id=DEMO_MCU_ID
    )
    await unit.start()
    out = io.StringIO()
    opts = CalibrateOptions(
        config=_config(tmp_path),
        address=UnitAddress("ble", "FOOT-CAL"),
        hold_s=2.0,
        out=out,
        ble_backend=bumble_backend(adapter, mtu=247),
        source_done=unit.finished.is_set,
    )
    try:
        with pytest.raises(TooFewFacesError, match=r"only 3 distinct faces.*9 more faces"):
            await calibrate_session(opts)
    finally:
        await unit.stop()
        await adapter.close()
    text = out.getvalue()
    assert f"MCU id {DEMO_MCU_ID.hex()}" in text and text.count("captured:") == 3
    (capture,) = (tmp_path / "sessions").glob("calibrate-*.mcap")
    from footnav.device.files.capture import read_capture_info

    assert read_capture_info(capture).units[0].settings["rate_hz"] == 125.0
