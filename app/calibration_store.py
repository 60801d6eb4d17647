"""Calibration files: one JSON file per unit, named by its MCU id, in a user folder.

Folder (first that applies): the configuration's ``calibration.dir``; ``$FOOTNAV_CALIBRATION_DIR``;
``$XDG_CONFIG_HOME/footnav/calibration``; ``~/.config/footnav/calibration``.

File ``<mcu id hex>.json``::

    {"format": "footnav-calibration", "mcu_id": "464e4156...", "created_utc": "...",
     "footnav_version": "...", "source": "how it was made",
     "stream": "which output the fit was made on, e.g. raw IMU 0x28, IMU mask 0x0F, with temperature",
     "calibration": {model_version, parameters, 1σ, residual RMS, ... (ImuCalibration.to_dict)}}

JSON rather than TOML: the standard library writes it (``tomllib`` only reads), and the file is
written by footnav, not by hand.

The fit is made on the raw IMU registers (0x28) and applied to the calibrated-IMU stream (0x40) that
sessions navigate. The two agree on units whose firmware applies no calibration of its own (low-cost
units, the emulated one); on a factory-calibrated board the 0x40 output is already corrected, and
``calibration.apply = false`` should be set for it.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from footnav.device.files.capture import footnav_version
from footnav.pipeline.calibration.model import CalibrationError, ImuCalibration

if TYPE_CHECKING:
    from footnav.app.config import Config

ENV_DIR: Final = "FOOTNAV_CALIBRATION_DIR"
FORMAT: Final = "footnav-calibration"


def calibration_dir(config: Config | None = None) -> Path:
    """The folder calibration files are read from and written to (see the module docstring)."""
    if config is not None and config["calibration.dir"]:
        return Path(config["calibration.dir"]).expanduser()
    env = os.environ.get(ENV_DIR)
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CONFIG_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".config"
    return base / "footnav" / "calibration"


def calibration_path(folder: Path, mcu_id: bytes) -> Path:
    """``folder/<mcu id hex>.json``."""
    return folder / f"{mcu_id.hex()}.json"


@dataclass(frozen=True, slots=True)
class StoredCalibration:
    """A calibration file read back."""

    path: Path
    mcu_id: str
    created_utc: str
    source: str
    calibration: ImuCalibration
    stream: str = ""

    def document(self) -> dict[str, Any]:
        """The file's content (what :func:`stored_calibration` reads back), as a capture keeps it."""
        return {
            "format": FORMAT,
            "mcu_id": self.mcu_id,
            "created_utc": self.created_utc,
            "source": self.source,
            "stream": self.stream,
            "calibration": self.calibration.to_dict(),
        }

    def describe(self) -> str:
        """One line for the terminal: which file, when, how good."""
        cal = self.calibration
        temp = (
            f"temperature terms about {cal.t_ref_c:.1f} °C"
            if cal.temperature_model
            else "no temperature terms (9-parameter model)"
        )
        return (
            f"calibration {self.path} (MCU id {self.mcu_id}, {self.created_utc}, fitted on {self.stream or '?'}, "
            f"{cal.n_faces} faces, "
            f"residual RMS {1e3 * cal.residual_rms_mps2:.2f} mm/s², {temp})"
        )


def save_calibration(
    folder: Path, mcu_id: bytes, calibration: ImuCalibration, *, source: str, stream: str = ""
) -> Path:
    """Write (or replace) the unit's calibration file atomically; returns its path.

    Raises
    ------
    OSError
        the folder cannot be created or written.
    """
    folder.mkdir(parents=True, exist_ok=True)
    path = calibration_path(folder, mcu_id)
    doc = {
        "format": FORMAT,
        "mcu_id": mcu_id.hex(),
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "footnav_version": footnav_version(),
        "source": source,
        "stream": stream,
        "calibration": calibration.to_dict(),
    }
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    os.replace(tmp, path)
    return path


def load_calibration(folder: Path, mcu_id: bytes) -> StoredCalibration | None:
    """The unit's calibration file, or None if there is none.

    Raises
    ------
    CalibrationError
        the file exists but cannot be read or is not a footnav calibration.
    """
    path = calibration_path(folder, mcu_id)
    if not path.is_file():
        return None
    try:
        doc: Any = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise CalibrationError(f"cannot read the calibration file {path}: {exc}") from exc
    return stored_calibration(path, doc, mcu_id)


def stored_calibration(path: Path, doc: Any, mcu_id: bytes) -> StoredCalibration:
    """A calibration file's document ``doc`` (read from ``path``, or kept in a capture) for the unit ``mcu_id``.

    Raises
    ------
    CalibrationError
        ``doc`` is not a footnav calibration, or one of another unit (a file renamed or copied).
    """
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or not isinstance(doc.get("calibration"), dict):
        raise CalibrationError(f"{path} is not a footnav calibration file; remove it or run `footnav calibrate`")
    if doc.get("mcu_id", mcu_id.hex()) != mcu_id.hex():
        raise CalibrationError(
            f"{path} is the calibration of another unit (MCU id {doc['mcu_id']}, not {mcu_id.hex()}): a file "
            "renamed or copied; remove it, or calibrate this unit with `footnav calibrate`"
        )
    return StoredCalibration(
        path=path,
        mcu_id=mcu_id.hex(),
        created_utc=str(doc.get("created_utc", "?")),
        source=str(doc.get("source", "")),
        calibration=ImuCalibration.from_dict(doc["calibration"]),
        stream=str(doc.get("stream", "")),
    )


def any_calibrations(folder: Path) -> bool:
    """True if the folder holds at least one calibration file (only then is a unit asked its MCU id)."""
    return folder.is_dir() and any(folder.glob("*.json"))
