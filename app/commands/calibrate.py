"""``footnav calibrate``: the guided icosahedron procedure in the terminal, and the calibration file.

The unit is asked for its MCU id, then started in raw IMU output with temperature (0x28, IMU mask
0x0F by default: the four IMUs of a MIMU board, averaged per sample as its combined output is); its
samples go to :class:`footnav.pipeline.calibration.procedure.FaceCollector`, whose events are printed as they
come: still, face captured (with its quality), moved, face seen before, done. The result is written to
the unit's calibration file (:mod:`footnav.app.calibration_store`), which ``live`` and ``replay`` then apply.

Sources: a live unit (``--port``, ``--ble``), a capture recorded by an earlier ``footnav calibrate``
(``--capture FILE``: the same driver calls consume the captured bytes, so the same faces are found),
or ``--demo``: an emulated miscalibrated unit on a pseudo-terminal that turns through the icosahedron
faces by itself (:mod:`footnav.device.emulator.sensors.icosahedron`); the demo also prints the errors against its truth.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Final

from footnav.app.calibration_store import calibration_dir, save_calibration
from footnav.app.config import Config
from footnav.app.feet import new_session_id, open_capture
from footnav.app.session import UnitAddress, open_unit_link
from footnav.device.emulator.sensors.icosahedron import MISCALIBRATED_MCU_ID as DEMO_MCU_ID
from footnav.device.files.capture import CaptureWriter, UnitHeader, read_capture_info
from footnav.device.links.base import ByteLink
from footnav.device.links.replay import CaptureReplayLink
from footnav.device.modes import RawImuMode
from footnav.device.protocol import raw_imu
from footnav.device.unit import Batch, OpenShoeUnit
from footnav.pipeline.calibration.model import (
    PARAM_NAMES,
    STANDARD_GRAVITY_MPS2,
    TOLERANCE,
    CalibrationError,
    ImuCalibration,
)
from footnav.pipeline.calibration.procedure import CAPTURE_S, MAX_FACES, FaceCollector
from footnav.pipeline.errors import FootnavError, InputFormatError

if TYPE_CHECKING:
    from footnav.device.emulator.sensors.icosahedron import Miscalibration
    from footnav.device.emulator.serving.pty import PtyShoeServer
    from footnav.device.links.ble import BleBackend

CAPTURE_MODE: Final = "calibration_raw_imu"
"""``settings.mode`` of a calibration capture's unit header."""
BASE_RATE_HZ: Final = 1000.0
BLE_RATE_DIVIDER: Final = 3
"""Over BLE the raw output runs at 125 Hz: four IMUs with temperature are 66-byte packets, 66 kB/s at
1 kHz, far more than a BLE link carries (about 16 kB/s at the minimum MTU)."""
IDLE_S: Final = 1.0
LOW_RATE_HOLD_S: Final = 8.0


@dataclass(frozen=True)
class CalibrateOptions:
    """What ``footnav calibrate`` was asked for (exactly one of ``address``, ``capture_file``, ``demo``).

    Attributes
    ----------
    imu_mask
        IMUs whose raw outputs are averaged (0x0F: a MIMU board's four).
    rate_divider_log2
        raw output every 2**k samples of the 1 kHz base rate (None: 0 on serial,
        :data:`BLE_RATE_DIVIDER` over BLE).
    hold_s
        still time averaged per face (None: 2 s at 1 kHz, 8 s below 500 Hz: the divided raw
        output is decimated, not averaged, so fewer samples need a longer hold for the same accuracy).
    allow_no_temperature
        fit the 9-parameter model when the temperature is unobservable.
    capture
        write a capture of the procedure into ``sessions.sessions_dir``.
    demo_pace
        emulator speed (``math.inf``: as fast as read).
    out
        where the procedure is narrated (tests pass a buffer).
    ble_backend
        tests only: the bleak backend.
    source_done
        tests only: True once an emulated unit has sent everything (the procedure then
        ends with the faces it has, as at the end of a capture).
    """

    config: Config
    address: UnitAddress | None = None
    capture_file: Path | None = None
    demo: bool = False
    imu_mask: int = 0x0F
    rate_divider_log2: int | None = None
    hold_s: float | None = None
    allow_no_temperature: bool = False
    max_faces: int = MAX_FACES
    capture: bool = True
    demo_pace: float = 10.0
    demo_seed: int = 3
    out: IO[str] | None = None
    ble_backend: BleBackend | None = None
    source_done: Callable[[], bool] | None = None


@dataclass
class CalibrateResult:
    """What the procedure produced."""

    calibration: ImuCalibration | None = None
    mcu_id: bytes | None = None
    path: Path | None = None
    capture_path: Path | None = None
    faces: int = 0


def _say(opts: CalibrateOptions, text: str) -> None:
    print(text, file=opts.out or sys.stdout, flush=True)


def parameter_table(cal: ImuCalibration, truth: Miscalibration | None = None) -> list[str]:
    """The fitted parameters with 1σ (and, given the truth, the error and the issue's tolerance)."""
    scale = {"k": (1e2, "%", 1.0), "l": (math.degrees(1.0), "°", 0.0), "b": (1e3 / STANDARD_GRAVITY_MPS2, "mg", 0.0)}
    tol = {
        "k": TOLERANCE["scale"] * 1e2,
        "l": math.degrees(TOLERANCE["misalignment_rad"]),
        "b": TOLERANCE["acc_bias_mps2"] * 1e3 / STANDARD_GRAVITY_MPS2,
    }
    ref = None if truth is None else truth.theta_at(cal.t_ref_c)
    head = f"{'parameter':<10}{'value':>12}{'1σ':>10}  unit"
    if ref is not None:
        head += f"{'truth':>12}{'error':>10}{'tolerance':>11}"
    lines = [head]
    for i, name in enumerate(PARAM_NAMES):
        kind = name.split("_")[0]
        if kind in scale:
            f, unit, offset = scale[kind]
            value = (cal.theta[i] - offset) * f
            line = f"{name:<10}{value:>12.4f}{cal.theta_sigma[i] * f:>10.4f}  {unit:<6}"
            if ref is not None:
                err = (cal.theta[i] - ref[i]) * f
                line += f"{(ref[i] - offset) * f:>12.4f}{err:>10.4f}{tol[kind]:>11.3f}"
        else:
            unit = "1/°C" if kind == "kt" else "mg/°C"
            f = 1.0 if kind == "kt" else 1e3 / STANDARD_GRAVITY_MPS2
            line = f"{name:<10}{cal.theta[i] * f:>12.3g}{cal.theta_sigma[i] * f:>10.2g}  {unit:<6}"
            if ref is not None:
                line += f"{ref[i] * f:>12.3g}{(cal.theta[i] - ref[i]) * f:>10.2g}"
        lines.append(line)
    for j, axis in enumerate("xyz"):
        b, s = math.degrees(cal.gyr_bias_radps[j]), math.degrees(cal.gyr_bias_sigma_radps[j])
        line = f"{'bg_' + axis:<10}{b:>12.4f}{s:>10.4f}  {'°/s':<6}"
        if truth is not None:
            tb = math.degrees(truth.gyr_bias_at(cal.t_ref_c)[j])
            line += f"{tb:>12.4f}{b - tb:>10.4f}{math.degrees(TOLERANCE['gyr_bias_radps']):>11.3f}"
        lines.append(line)
    faces = " ".join(f"{1e3 * r:.2f}" for r in cal.face_residual_rms_mps2)
    lines.append(f"residual RMS per face, mm/s²: {faces}")
    temp = f"reference temperature {cal.t_ref_c:.2f} °C" if cal.temperature_model else "no temperature terms"
    lines.append(
        f"k: scale − 1; l: misalignment; b: bias at the reference; {temp}; residual RMS "
        f"{1e3 * cal.residual_rms_mps2:.2f} mm/s² over {cal.n_windows} windows of {cal.n_faces} faces"
    )
    return lines


def _never() -> bool:
    return False


def calibration_header(port: str, transport: str, imu_mask: int, rate_divider_log2: int) -> UnitHeader:
    """The capture header of a calibration procedure (``settings.mode`` = :data:`CAPTURE_MODE`)."""
    return UnitHeader(
        foot="foot",
        unit="OpenShoe/MIMU/Oblu, raw IMU output with temperature (0x28), calibration procedure",
        command_set="openshoe (2015 set, 2014 probed)",
        transport=transport,
        port=port,
        settings={
            "mode": CAPTURE_MODE,
            "imu_mask": imu_mask,
            "rate_divider_log2": rate_divider_log2,
            "rate_hz": BASE_RATE_HZ / 2**rate_divider_log2,
        },
    )


async def _procedure(
    unit: OpenShoeUnit,
    opts: CalibrateOptions,
    result: CalibrateResult,
    source_done: Callable[[], bool],
    capture: CaptureWriter | None,
) -> FaceCollector:
    """MCU id, raw output with temperature, then faces until the collector finishes or the stream ends."""
    result.mcu_id = await unit.request_mcu_id()
    _say(opts, f"unit {unit.link.name}: MCU id {result.mcu_id.hex()}")
    if capture is not None:
        capture.event("foot", "mcu_id", mcu_id=result.mcu_id.hex())
    divider = opts.rate_divider_log2 or 0
    await unit.start(RawImuMode(opts.imu_mask, rate_divider_log2=divider, temperature=True))
    rate_hz = BASE_RATE_HZ / 2**divider
    hold_s = opts.hold_s if opts.hold_s is not None else (CAPTURE_S if rate_hz >= 500 else LOW_RATE_HOLD_S)
    collector = FaceCollector(
        rate_hz, capture_s=hold_s, max_faces=opts.max_faces, allow_no_temperature=opts.allow_no_temperature
    )
    _say(
        opts,
        f"put the unit in the icosahedron and hold it still on one face for {hold_s:g} s; "
        f"{collector.min_faces} to {opts.max_faces} faces are needed",
    )
    batches = unit.batches()
    pending: asyncio.Future[Batch] | None = None
    async with contextlib.aclosing(batches):
        try:
            while collector.state != "finished":
                fut = pending if pending is not None else asyncio.ensure_future(anext(batches))
                pending = fut
                done, _ = await asyncio.wait({fut}, timeout=IDLE_S)
                if not done:
                    if source_done():
                        break
                    continue
                pending = None
                try:
                    batch = fut.result()
                except StopAsyncIteration:
                    break
                if not isinstance(batch, raw_imu.RawImuBatch):
                    continue
                raw_temp = batch.temperature_raw
                temp = None if raw_temp is None else raw_imu.temperature_c(raw_temp).mean(axis=1)
                for ev in collector.feed(
                    batch.t_s, batch.acc_b_mps2.mean(axis=1), batch.gyr_b_radps.mean(axis=1), temp
                ):
                    result.faces = len(collector.faces)
                    _say(opts, f"[{len(collector.faces):2d}/{opts.max_faces} faces] {ev.message}")
        finally:
            if pending is not None and not pending.done():
                pending.cancel()
                with contextlib.suppress(asyncio.CancelledError, StopAsyncIteration):
                    await pending
    return collector


async def calibrate_session(opts: CalibrateOptions) -> CalibrateResult:
    """Run the procedure from the chosen source and save the calibration; see the module docstring.

    Raises
    ------
    CalibrationError
        the faces do not determine the calibration (the message says what to redo).
    DeviceError, InputFormatError
        the unit or the capture cannot be used.
    """
    result = CalibrateResult()
    truth: Miscalibration | None = None
    with contextlib.ExitStack() as stack:
        capture: CaptureWriter | None = None
        tap = None
        source_done: Callable[[], bool] = opts.source_done or _never
        link: ByteLink
        capture_file = opts.capture_file
        if capture_file is not None:
            info = read_capture_info(capture_file)
            if not info.units or info.units[0].settings.get("mode") != CAPTURE_MODE:
                raise InputFormatError(
                    f"{opts.capture_file} is not a calibration capture (recorded by `footnav calibrate`); "
                    "its unit streamed no raw IMU output with temperature"
                )
            settings = info.units[0].settings
            opts = dataclasses.replace(
                opts,
                imu_mask=int(settings.get("imu_mask", opts.imu_mask)),
                rate_divider_log2=int(settings.get("rate_divider_log2", 0)),
            )
            link = CaptureReplayLink(capture_file, info.units[0].foot, speed=math.inf)
            _say(opts, f"calibrating from the capture {opts.capture_file}")
        else:
            address = opts.address
            transport: str = "serial" if address is None else address.transport
            if opts.demo:
                server, truth = _demo_server(opts)
                stack.enter_context(server)
                address = UnitAddress("serial", server.port)
                transport = "pty (emulator)"
                source_done = server.finished.is_set
                _say(opts, f"demo: an emulated miscalibrated unit on {server.port} turns through the icosahedron")
            assert address is not None
            if opts.rate_divider_log2 is None:
                divider = BLE_RATE_DIVIDER if address.transport == "ble" else 0
                opts = dataclasses.replace(opts, rate_divider_log2=divider)
            session_id = new_session_id("calibrate")
            capture = open_capture(
                opts.config, session_id, enabled=opts.capture, extra={"command": "footnav calibrate"}
            )
            if capture is not None:
                stack.callback(_close_capture, capture, result)
                tap = capture.add_unit(
                    calibration_header(str(address), transport, opts.imu_mask, opts.rate_divider_log2 or 0)
                )
                result.capture_path = capture.path
            link = await open_unit_link(address, capture=tap, ble_backend=opts.ble_backend)
        unit = OpenShoeUnit(link, capture=tap)
        try:
            collector = await _procedure(unit, opts, result, source_done, capture)
        finally:
            if opts.capture_file is None:
                with contextlib.suppress(FootnavError, OSError):
                    await unit.stop()
            with contextlib.suppress(FootnavError, OSError):
                await unit.close()
    if collector.calibration is None:
        if collector.state == "finished":  # failed after the last face
            raise collector.last_error or CalibrationError("the calibration could not be determined")
        result.calibration = collector.finish()  # the stream ended: the fit from the faces so far, or why not
    else:
        result.calibration = collector.calibration
    for line in parameter_table(result.calibration, truth):
        _say(opts, line)
    assert result.mcu_id is not None
    folder = calibration_dir(opts.config)
    source = "demo (emulated unit)" if opts.demo else str(opts.capture_file or opts.address)
    stream = (
        f"raw IMU 0x28, IMU mask 0x{opts.imu_mask:02X}, {BASE_RATE_HZ / 2 ** (opts.rate_divider_log2 or 0):g} Hz"
        + (", with temperature" if result.calibration.temperature_model else "")
    )
    result.path = save_calibration(folder, result.mcu_id, result.calibration, source=source, stream=stream)
    _say(opts, f"saved {result.path}: applied whenever this unit connects or its capture is replayed")
    return result


def _close_capture(capture: CaptureWriter, result: CalibrateResult) -> None:
    """Close the capture; one that no unit ever answered (the port could not be opened, the unit was
    silent) holds nothing worth keeping, so it is removed."""
    capture.close()
    if capture.rx_bytes == 0:
        capture.path.unlink(missing_ok=True)
        result.capture_path = None


def _demo_server(opts: CalibrateOptions) -> tuple[PtyShoeServer, Miscalibration]:
    """The emulated miscalibrated unit performing the procedure, served on a pty."""
    from footnav.device.emulator.sensors.icosahedron import (
        Miscalibration,
        miscalibrated_signals,
        simulate_icosahedron,
        warm_up_c,
    )
    from footnav.device.emulator.serving.pty import PtyShoeServer

    truth = simulate_icosahedron(BASE_RATE_HZ)
    temp = warm_up_c(truth.t_s)
    errors = Miscalibration()
    acc, gyr = miscalibrated_signals(
        truth.acc_b_mps2, truth.gyr_b_radps, temp, BASE_RATE_HZ, errors=errors, seed=opts.demo_seed
    )
    server = PtyShoeServer(truth.t_s, acc, gyr, speed=opts.demo_pace, record=False, temp_c=temp, mcu_id=DEMO_MCU_ID)
    return server, errors


def run_calibrate(opts: CalibrateOptions) -> int:
    """``footnav calibrate``; returns the exit code (2 with what to redo when the fit is refused)."""
    try:
        asyncio.run(calibrate_session(opts))
    except CalibrationError as exc:
        print(f"footnav: calibration not saved: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted: no calibration saved", file=sys.stderr)
        return 130
    return 0
