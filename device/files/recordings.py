"""Loaders for recordings made by other tools: PyShoe ``.mat``, x-io CSV, OpenShoe text, generic CSV,
raw logs of an OpenShoe/MIMU unit's stream (``footnav.device.files.vendor_log``).

Each loader converts to SI units once, here, and returns a :class:`Recording`; nothing downstream
knows which tool wrote the file. Ground truth, where a format carries it, is converted to footnav's
right-handed, z-up frame. Loading is the only job of this module: it reads files, computes nothing.
"""

from __future__ import annotations

import csv
import math
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from footnav.pipeline.errors import InputFormatError
from numpy.typing import NDArray

F64 = NDArray[np.float64]
G0_MPS2 = 9.80665
DEG = math.pi / 180.0


@dataclass(frozen=True)
class Recording:
    """IMU samples of one recording, in SI units, with what is known about the truth.

    Attributes
    ----------
    name
        file stem.
    format
        loader key (``pyshoe``, ``xio``, ``openshoe``, ``csv``).
    t_s
        (n,) sample times, s, as recorded (may hold duplicates and jitter).
    acc_b_mps2, gyr_b_radps
        (n, 3) body-frame specific force and angular rate.
    rate_hz
        nominal rate, from the median sample interval.
    profile
        name of the unit profile (``footnav.pipeline.navigation.profiles``) that describes the sensor.
    gt_pos_m
        (n, 3) ground-truth position per sample (right-handed, z up), or None.
    closed_loop
        the walker returned to the start (loop-closure error is meaningful).
    notes
        facts about the file a person should know (handedness conversions, dropped rows).
    t_start_s
        time of the first sample on the file's own clock, s (``t_s`` starts at 0): what puts two feet's
        files on one clock.
    """

    name: str
    format: str
    t_s: F64
    acc_b_mps2: F64
    gyr_b_radps: F64
    rate_hz: float
    profile: str
    gt_pos_m: F64 | None = None
    closed_loop: bool = False
    notes: list[str] = field(default_factory=list)
    t_start_s: float = 0.0

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


PLAUSIBLE_RATE_HZ = (1.0, 100_000.0)
"""Sample rates a foot-mounted IMU recording can have, Hz: outside them the time column is in another
unit than the one assumed, or is not a time at all."""


def _nominal_rate(t_s: F64, path: Path | None = None) -> float:
    """The rate of the median positive time step, Hz, once the time stamps are known to be times.

    Raises
    ------
    InputFormatError
        a time stamp is not finite, time runs backwards, never increases, or gives a rate outside
        :data:`PLAUSIBLE_RATE_HZ` (the message names the row or the rate).
    """
    where = f"{path}: " if path is not None else ""
    bad = np.flatnonzero(~np.isfinite(t_s))
    if bad.size:
        raise InputFormatError(
            f"{where}time stamp {t_s[bad[0]]} at data row {bad[0] + 1} ({bad.size} not finite); "
            "expected a number in every row of the time column"
        )
    dt = np.diff(t_s)
    back = np.flatnonzero(dt < 0)
    if back.size:
        k = int(back[0]) + 1
        raise InputFormatError(
            f"{where}time runs backwards at data row {k + 1} ({t_s[k - 1]:.9g} then {t_s[k]:.9g}; "
            f"{back.size} such steps); expected time stamps in increasing order"
        )
    dt = dt[dt > 0]
    if dt.size == 0:
        raise InputFormatError(f"{where}the recording's time stamps never increase; expected time in seconds")
    rate_hz = float(1.0 / np.median(dt))
    lo, hi = PLAUSIBLE_RATE_HZ
    if not lo <= rate_hz <= hi:
        raise InputFormatError(
            f"{where}the time stamps give {rate_hz:.3g} samples a second, not a sensor's rate ({lo:g} to {hi:g} Hz); "
            "is the time column in another unit? (a generic CSV names it: --columns time=COL:ms)"
        )
    return rate_hz


def load_pyshoe_mat(path: Path) -> Recording:
    """PyShoe VICON trial (Wagstaff, Peretroukhin, Kelly 2019; doi 10.21227/v1z6-9z84).

    Fields ``ts`` (1×n, s), ``imu`` (n×6: m/s², rad/s), ``gt`` (n×3, m). The motion-capture frame is
    left-handed (north, east, up), so y is negated here to make it right-handed z-up.
    """
    mat = _loadmat_isolated(path)
    missing = [k for k in ("ts", "imu") if k not in mat]
    if missing:
        fields = sorted(k for k in mat if not k.startswith("__"))
        raise InputFormatError(
            f"{path} is not a PyShoe trial: footnav reads a .mat file only as a PyShoe VICON trial, with fields "
            f"ts (1×n times, s) and imu (n×6: m/s², rad/s); this one has "
            f"{', '.join(fields) if fields else 'no variables'} (missing {', '.join(missing)})"
        )
    t = _mat_f64(mat, "ts", path).ravel()
    imu = _mat_f64(mat, "imu", path)
    if t.size < 2 or imu.ndim != 2 or imu.shape != (t.size, 6):
        raise InputFormatError(
            f"{path}: expected ts of n >= 2 times and imu of shape (n, 6), got {t.shape}, {imu.shape}"
        )
    gt = None
    notes = []
    if "gt" in mat:
        gt = _mat_f64(mat, "gt", path)
        if gt.ndim == 2 and gt.shape == (t.size, 3):
            gt = gt.copy()
            gt[:, 1] *= -1.0
            notes.append("ground truth converted from the left-handed VICON frame (y negated)")
        else:
            gt = None
            notes.append("ground truth is not one (x, y, z) row per IMU sample; ignored")
    rate_hz = _nominal_rate(t, path)  # first: a bad first time stamp is named, never subtracted
    return Recording(
        name=path.stem,
        format="pyshoe",
        t_s=t - t[0],
        t_start_s=float(t[0]),
        acc_b_mps2=imu[:, :3].copy(),
        gyr_b_radps=imu[:, 3:].copy(),
        rate_hz=rate_hz,
        profile="gx3",
        gt_pos_m=gt,
        notes=notes,
    )


def _loadmat_isolated(path: Path) -> dict[str, object]:
    """``scipy.io.loadmat`` in a child process (``footnav.device.files.mat_reader``): its C reader can crash on a
    corrupt file, which must be an error message, not a crash.

    Raises
    ------
    InputFormatError
        the file is not readable as a MATLAB .mat file, or crashed the reader.
    """
    from footnav.device.files.mat_reader import ReaderCrashedError, load_mat

    try:
        return load_mat(path)
    except ReaderCrashedError:
        raise InputFormatError(f"{path}: corrupt .mat file (it crashed the MATLAB reader)") from None
    except Exception as exc:  # scipy raises many kinds on a corrupt file
        raise InputFormatError(
            f"{path}: not a MATLAB .mat file readable as a PyShoe trial ({type(exc).__name__}: {exc})"
        ) from None


def _mat_f64(mat: dict[str, object], name: str, path: Path) -> F64:
    try:
        return np.asarray(mat[name], dtype=np.float64)
    except (ValueError, TypeError):
        raise InputFormatError(f"{path}: field {name} is not numeric") from None


XIO_COLUMNS = (
    "Time (s)",
    "Gyroscope X (deg/s)",
    "Gyroscope Y (deg/s)",
    "Gyroscope Z (deg/s)",
    "Accelerometer X (g)",
    "Accelerometer Y (g)",
    "Accelerometer Z (g)",
)


def load_xio_csv(path: Path) -> Recording:
    """x-io Technologies CSV (``Time (s)``, gyroscope in °/s, accelerometer in g).

    As in ``xioTechnologies/Gait-Tracking``'s sample data. Time stamps are kept as recorded
    (jittery, with duplicates); the navigator handles non-positive intervals.
    """
    header = _csv_header(path)
    if tuple(h.strip() for h in header[: len(XIO_COLUMNS)]) != XIO_COLUMNS:
        raise InputFormatError(f"{path}: expected an x-io CSV with columns {', '.join(XIO_COLUMNS)}; got {header}")
    data = _read_numeric_csv(path, skip=1, ncols=7)
    t = data[:, 0]
    rate_hz = _nominal_rate(t, path)  # first: a bad first time stamp is named, never subtracted
    return Recording(
        name=path.stem,
        format="xio",
        t_s=t - t[0],
        t_start_s=float(t[0]),
        acc_b_mps2=data[:, 4:7] * G0_MPS2,
        gyr_b_radps=data[:, 1:4] * DEG,
        rate_hz=rate_hz,
        profile="generic",
        closed_loop=True,
        notes=["x-io sample walk: the foot ends where it started"],
    )


def load_openshoe_txt(path: Path) -> Recording:
    """OpenShoe inertial log (``Measurement_*/data_inert.txt``, MicroStrain 3DM-GX2 at 250 Hz).

    Two header lines, then rows ``0xcb a_x a_y a_z [g] ar_x ar_y ar_z [rad/s] counter checksum Nr
    filtered_ts unfiltered_ts predicted_ts freq m_x m_y m_z``. The filtered time stamp is used.
    """
    rows: list[list[float]] = []
    skipped = 0
    with path.open("r", encoding="latin-1") as f:
        lines = f.readlines()
    if not any("a_x [g]" in ln for ln in lines[:5]):
        raise InputFormatError(f"{path}: expected an OpenShoe inertial log (header with 'a_x [g]')")
    for line in lines:
        parts = line.split()
        if not parts or parts[0].lower() != "0xcb":
            continue
        try:
            rows.append([float(parts[i]) for i in (1, 2, 3, 4, 5, 6, 10)])
        except (ValueError, IndexError):
            skipped += 1
    if len(rows) < 2:
        raise InputFormatError(f"{path}: no data rows starting with 0xcb")
    data = np.array(rows)
    t = data[:, 6]
    notes = ["OpenShoe walk: the walker returned to the start within ±1 cm"]
    if skipped:
        notes.append(f"{skipped} malformed rows skipped")
    rate_hz = _nominal_rate(t, path)  # first: a bad first time stamp is named, never subtracted
    return Recording(
        name=path.stem,
        format="openshoe",
        t_s=t - t[0],
        t_start_s=float(t[0]),
        acc_b_mps2=data[:, 0:3] * G0_MPS2,
        gyr_b_radps=data[:, 3:6].copy(),
        rate_hz=rate_hz,
        profile="gx3",
        closed_loop=True,
        notes=notes,
    )


ACC_UNITS: Mapping[str, float] = {"m/s2": 1.0, "g": G0_MPS2, "mg": G0_MPS2 / 1000.0}
GYR_UNITS: Mapping[str, float] = {"rad/s": 1.0, "deg/s": DEG, "mrad/s": 1e-3}
TIME_UNITS: Mapping[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}


@dataclass(frozen=True)
class CsvMapping:
    """Which columns of a generic CSV hold what, and in which units.

    Attributes
    ----------
    time
        column name of the time stamp.
    acc, gyr
        three column names each.
    time_unit, acc_unit, gyr_unit
        keys of TIME_UNITS, ACC_UNITS, GYR_UNITS.
    profile
        unit profile of the sensor.
    closed_loop
        the walk ends at its start.
    gt
        three column names of a ground-truth position (right-handed, z up), m; read when the header has
        them (default ``gt_x_m``, ``gt_y_m``, ``gt_z_m``).
    """

    time: str = "t"
    acc: tuple[str, str, str] = ("ax", "ay", "az")
    gyr: tuple[str, str, str] = ("gx", "gy", "gz")
    time_unit: str = "s"
    acc_unit: str = "m/s2"
    gyr_unit: str = "rad/s"
    profile: str = "generic"
    closed_loop: bool = False
    gt: tuple[str, str, str] = ("gt_x_m", "gt_y_m", "gt_z_m")

    @staticmethod
    def parse(spec: str) -> CsvMapping:
        """From ``key=value`` pairs separated by commas, e.g.
        ``time=ts:ms,acc=ax;ay;az:g,gyr=wx;wy;wz:deg/s,profile=mpu6500x4``."""
        fields: dict[str, object] = {}
        for item in filter(None, (s.strip() for s in spec.split(","))):
            key, _, value = item.partition("=")
            names, _, unit = value.partition(":")
            if key == "time":
                fields["time"] = names
                if unit:
                    fields["time_unit"] = unit
            elif key == "gt":
                gt = tuple(names.split(";"))
                if len(gt) != 3:
                    raise InputFormatError(f"--columns gt= needs three column names separated by ';', got {names!r}")
                fields["gt"] = gt
            elif key in ("acc", "gyr"):
                cols = tuple(names.split(";"))
                if len(cols) != 3:
                    raise InputFormatError(f"--columns {key}= needs three column names separated by ';', got {names!r}")
                fields[key] = cols
                if unit:
                    fields[f"{key}_unit"] = unit
            elif key == "profile":
                fields["profile"] = value
            elif key == "closed_loop":
                fields["closed_loop"] = value.lower() in ("1", "true", "yes")
            else:
                raise InputFormatError(f"unknown --columns key {key!r}; use time, acc, gyr, gt, profile, closed_loop")
        return CsvMapping(**fields)  # type: ignore[arg-type]


def load_generic_csv(path: Path, mapping: CsvMapping | None = None) -> Recording:
    """A CSV with a header row; ``mapping`` says which columns and units (default t, ax.., gx.. in SI)."""
    m = mapping or CsvMapping()
    for unit, table, what in (
        (m.time_unit, TIME_UNITS, "time"),
        (m.acc_unit, ACC_UNITS, "acc"),
        (m.gyr_unit, GYR_UNITS, "gyr"),
    ):
        if unit not in table:
            raise InputFormatError(f"unknown {what} unit {unit!r}; known: {', '.join(table)}")
    header = [h.strip() for h in _csv_header(path)]
    # ground truth when the header has its columns, or when --columns names them (then they must be there)
    with_gt = m.gt != CsvMapping.gt or all(c in header for c in m.gt)
    wanted = [m.time, *m.acc, *m.gyr, *(m.gt if with_gt else ())]
    missing = [c for c in wanted if c not in header]
    if missing:
        if not any(header):
            what = "is empty" if _is_blank(path) else "starts with a blank line"
            raise InputFormatError(f"{path} {what}; expected a CSV with a header row naming its columns")
        noun = "column" if len(missing) == 1 else "columns"
        if all(_is_number(h) for h in header):
            raise InputFormatError(
                f"{path}: the first row is numbers, not a header; add a header row naming the columns "
                f"(--columns names which is which)"
            )
        found = f"{path}: {noun} {', '.join(missing)} not found; the header has {', '.join(header)}"
        if len(header) == 1 and (sep := next((c for c in ";\t|" if c in header[0]), None)):
            raise InputFormatError(
                f"{path}: its columns are separated by {sep!r} (header {header[0]}); footnav reads comma-separated CSV"
            )
        if mapping is None:
            raise InputFormatError(f"{found}; name its columns and units with --columns (the recordings guide)")
        raise InputFormatError(found)
    data = _read_numeric_csv(path, skip=1, ncols=len(header))[:, [header.index(c) for c in wanted]]
    t = data[:, 0] * TIME_UNITS[m.time_unit]
    rate_hz = _nominal_rate(t, path)  # first: a bad first time stamp is named, never subtracted
    return Recording(
        name=path.stem,
        format="csv",
        t_s=t - t[0],
        t_start_s=float(t[0]),
        acc_b_mps2=data[:, 1:4] * ACC_UNITS[m.acc_unit],
        gyr_b_radps=data[:, 4:7] * GYR_UNITS[m.gyr_unit],
        rate_hz=rate_hz,
        profile=m.profile,
        gt_pos_m=data[:, 7:10].copy() if with_gt else None,
        closed_loop=m.closed_loop,
    )


def _is_blank(path: Path) -> bool:
    """The file holds nothing but white space."""
    with path.open("rb") as f:
        return not f.read(1 << 16).strip()


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _csv_header(path: Path) -> list[str]:
    try:
        with path.open("r", newline="", encoding="utf-8-sig") as f:
            return next(csv.reader(f), [])
    except UnicodeDecodeError:
        raise InputFormatError(f"{path}: not a text CSV file") from None


def _read_numeric_csv(path: Path, skip: int, ncols: int) -> F64:
    """The rows after ``skip`` lines, by the compiled parser (``footnav.device.files.numeric_csv``) or, for what
    it leaves and on a first run (an empty numba cache: the command compiles the parser beside its other kernels),
    by ``np.loadtxt``: the same values."""
    from footnav.device.files.numeric_csv import read_plain_rows
    from footnav.pipeline.navigation.warm import cache_is_empty

    plain = None if cache_is_empty() else read_plain_rows(path.read_bytes(), skip)
    try:
        with warnings.catch_warnings():  # "no data" is reported below, as an error
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(path, delimiter=",", skiprows=skip, ndmin=2) if plain is None else plain
    except ValueError as exc:
        raise InputFormatError(f"{path}: non-numeric values in the data rows ({exc})") from None
    if data.shape[1] < ncols or data.shape[0] < 2:
        raise InputFormatError(f"{path}: expected at least 2 rows of {ncols} numeric columns, got {data.shape}")
    out: F64 = data
    return out


def load_mimu_log_recording(path: Path) -> Recording:
    """A raw binary log of an OpenShoe/MIMU unit's stream (``footnav.device.files.vendor_log``), at the
    rate its clock gives, with the MPU-6500 boards' profile."""
    from footnav.device.files.vendor_log import load_mimu_log  # with the protocol's decoders, for these files only

    t_s, acc, gyr, rate_hz, notes = load_mimu_log(path)
    return Recording(
        name=path.stem,
        format=MIMU_LOG_FORMAT,
        t_s=t_s,
        acc_b_mps2=acc,
        gyr_b_radps=gyr,
        rate_hz=rate_hz,
        profile="mpu6500x4",
        notes=notes,
    )


MIMU_LOG_FORMAT: Final = "mimu-log"
"""The loader key of raw logs of an OpenShoe/MIMU unit's stream (``footnav.device.files.vendor_log``)."""
FORMAT_NAMES: Mapping[str, str] = {
    "pyshoe": "a PyShoe .mat trial",
    "xio": "an x-io CSV",
    "openshoe": "an OpenShoe inertial log",
    "csv": "a generic CSV",
    MIMU_LOG_FORMAT: "a raw log of an OpenShoe/MIMU unit's stream",
}
"""What each format is, for messages."""

LOADERS: dict[str, Callable[[Path], Recording]] = {
    "pyshoe": load_pyshoe_mat,
    "xio": load_xio_csv,
    "openshoe": load_openshoe_txt,
    "csv": load_generic_csv,
    MIMU_LOG_FORMAT: load_mimu_log_recording,
}


def detect_format(path: Path) -> str:
    """Loader key for a file, from its content (magic bytes and header), not only its name.

    Raises
    ------
    InputFormatError
        the file is none of the known formats (the message lists them).
    """
    try:
        with path.open("rb") as f:
            head = f.read(512)
    except OSError as exc:
        raise InputFormatError(f"cannot read {path}: {exc.strerror}") from None
    if head.startswith(b"MATLAB 5.0 MAT-file"):
        return "pyshoe"
    if head.startswith(b"RRF"):
        raise InputFormatError(
            f"{path} is a Rerun recording (.rrd): footnav writes these, it does not navigate them; "
            f"open it with `rerun {path}`"
        )
    text = head.decode("latin-1")
    if "a_x [g]" in text or "Inertial data" in text:
        return "openshoe"
    if text.startswith("Time (s),Gyroscope X (deg/s)"):
        return "xio"
    if path.suffix.lower() == ".csv":
        return "csv"
    from footnav.device.files.vendor_log import looks_like_log

    if looks_like_log(head):
        return MIMU_LOG_FORMAT
    raise InputFormatError(
        f"{path}: unknown recording format; expected a PyShoe .mat, an x-io CSV, an OpenShoe "
        "data_inert.txt, a CSV with a header row (give the columns with --columns), or a raw log of an "
        "OpenShoe/MIMU unit's stream"
    )


def load_recording(path: Path, fmt: str | None = None, mapping: CsvMapping | None = None) -> Recording:
    """Load ``path`` with the loader for ``fmt`` (detected from the file when None)."""
    if path.is_dir():
        raise InputFormatError(f"{path} is a folder; expected a recording file")
    key = fmt or detect_format(path)
    if key not in LOADERS:
        raise InputFormatError(f"unknown format {key!r}; known: {', '.join(LOADERS)}")
    if mapping is not None and key != "csv":
        how = "was given as" if fmt else "is"
        raise InputFormatError(
            f"{path} {how} {FORMAT_NAMES.get(key, key)}, whose columns are known: --columns applies to a generic "
            "CSV only; drop it, or give --format csv to read the file as a generic CSV with those columns"
        )
    try:
        if key == "csv":
            return load_generic_csv(path, mapping)
        return LOADERS[key](path)
    except OSError as exc:
        raise InputFormatError(f"cannot read {path}: {exc.strerror or exc}") from None
