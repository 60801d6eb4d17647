"""Fuzzing the loaders, the capture reader and the navigator behind them (hypothesis).

Every input either loads into consistent arrays or is refused with an ``InputFormatError`` that a
person can read; whatever loads navigates without an exception other than ``FootnavError`` and
without leaving non-finite or runaway estimates unflagged. Seeds are real files from ``../shared/data``
(their first lines) and valid files written here, mutated byte- and line-wise.

Briefly in the suite; at length on demand::

    FOOTNAV_FUZZ_EXAMPLES=20000 .venv/bin/python -m pytest tests/test_fuzz_inputs.py tests/test_decoders.py
"""

from __future__ import annotations

import functools
import io
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from footnav.device.files.capture import CaptureWriter, UnitHeader, iter_capture
from footnav.device.files.recordings import Recording, load_recording
from footnav.pipeline.errors import FootnavError, InputFormatError
from footnav.pipeline.navigation.navigator import NavConfig, navigate
from footnav.pipeline.navigation.profiles import get_profile
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

EXAMPLES = int(os.environ.get("FOOTNAV_FUZZ_EXAMPLES", "40"))
# the suite's short run is the same every time (a CI run must not depend on luck); a long run explores
FUZZ = settings(
    max_examples=EXAMPLES,
    deadline=None,
    derandomize="FOOTNAV_FUZZ_EXAMPLES" not in os.environ,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def _head(path: Path, lines: int) -> bytes:
    if not path.exists():
        pytest.skip(f"{path} not present")  # the suite's real-data fixture documents ../shared/data
    with path.open("rb") as f:
        return b"".join(f.readline() for _ in range(lines))


def _mat_bytes(fields: dict[str, object]) -> bytes:
    buf = io.BytesIO()
    scipy.io.savemat(buf, fields)
    return buf.getvalue()


def _valid_mat(n: int = 400) -> bytes:
    rng = np.random.default_rng(0)
    imu = np.column_stack([rng.normal(0, 0.1, (n, 2)), 9.81 + rng.normal(0, 0.1, n), rng.normal(0, 0.01, (n, 3))])
    return _mat_bytes({"ts": (np.arange(n) / 200.0)[None, :], "imu": imu, "gt": np.zeros((n, 3))})


def _mutate(data: st.DataObject, seed: bytes, *, text: bool) -> bytes:
    """One of: truncate, flip bytes, splice junk, duplicate/drop/garble lines (text)."""
    buf = bytearray(seed)
    for _ in range(data.draw(st.integers(1, 4), label="mutations")):
        kind = data.draw(st.sampled_from(["truncate", "flip", "splice"] + (["lines"] if text else [])))
        if not buf:
            break
        at = data.draw(st.integers(0, len(buf) - 1), label="at")
        if kind == "truncate":
            del buf[at:]
        elif kind == "flip":
            buf[at] ^= data.draw(st.integers(1, 255), label="xor")
        elif kind == "splice":
            junk = data.draw(
                st.binary(max_size=40) if not text else st.text(alphabet=",.-e0123456789naifNAIF \n\t", max_size=40)
            )
            buf[at:at] = junk if isinstance(junk, bytes) else junk.encode()
        else:
            lines = bytes(buf).split(b"\n")
            i = data.draw(st.integers(0, len(lines) - 1), label="line")
            op = data.draw(st.sampled_from(["dup", "drop", "swap", "nan", "empty"]))
            if op == "dup":
                lines.insert(i, lines[i])
            elif op == "drop":
                del lines[i]
            elif op == "swap" and i + 1 < len(lines):
                lines[i], lines[i + 1] = lines[i + 1], lines[i]
            elif op == "nan":
                lines[i] = b",".join(b"nan" for _ in lines[i].split(b","))
            else:
                lines[i] = b""
            buf = bytearray(b"\n".join(lines))
    return bytes(buf)


def _check_loaded(rec: Recording) -> None:
    n = len(rec)
    assert rec.acc_b_mps2.shape == (n, 3) and rec.gyr_b_radps.shape == (n, 3)
    assert np.isfinite(rec.rate_hz) and rec.rate_hz > 0
    if rec.gt_pos_m is not None:
        assert rec.gt_pos_m.shape == (n, 3)
    cfg = NavConfig(profile=get_profile(rec.profile))
    try:
        with np.errstate(all="ignore"):
            nav, stats = navigate(rec.t_s, rec.acc_b_mps2, rec.gyr_b_radps, rec.rate_hz, cfg)
    except FootnavError:
        return
    if nav is None:
        return
    # bad samples and bad time steps are skipped and counted, never spread into the estimate
    assert np.all(np.isfinite(nav.pos_n_m)), stats
    assert np.all(np.isfinite(nav.quat_nb_wxyz)), stats


def _load(tmp: Path, name: str, content: bytes) -> None:
    path = tmp / name
    path.write_bytes(content)
    try:
        rec = load_recording(path)
    except InputFormatError as exc:
        assert str(exc)  # a message, not an empty error
        return
    _check_loaded(rec)


@FUZZ
@given(data=st.data())
def test_mutated_xio_csv(data: st.DataObject) -> None:
    seed = _head(DATA / "xio-gait-tracking" / "short_walk.csv", 600)
    with tempfile.TemporaryDirectory() as tmp:
        _load(Path(tmp), "walk.csv", _mutate(data, seed, text=True))


@FUZZ
@given(data=st.data())
def test_mutated_openshoe_log(data: st.DataObject) -> None:
    seed = _head(DATA / "openshoe" / "data_inert.txt", 600)
    with tempfile.TemporaryDirectory() as tmp:
        _load(Path(tmp), "data_inert.txt", _mutate(data, seed, text=True))


@FUZZ
@given(data=st.data())
def test_mutated_pyshoe_mat(data: st.DataObject) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        _load(Path(tmp), "trial.mat", _mutate(data, _valid_mat(), text=False))


@FUZZ
@given(
    ts=st.sampled_from([np.zeros((1, 0)), np.arange(50.0)[None, :], np.full((1, 50), np.nan), np.ones((3, 3)), "x"]),
    imu=st.sampled_from([np.zeros((50, 6)), np.zeros((50, 5)), np.full((50, 6), np.inf), np.zeros((0, 6)), 7.0]),
    gt=st.sampled_from([None, np.zeros((50, 3)), np.zeros((4, 3)), np.zeros((50, 2))]),
)
def test_pyshoe_mat_with_wrong_fields(ts: object, imu: object, gt: object) -> None:
    fields = {"ts": ts, "imu": imu} | ({} if gt is None else {"gt": gt})
    with tempfile.TemporaryDirectory() as tmp:
        _load(Path(tmp), "trial.mat", _mat_bytes(fields))


@FUZZ
@given(content=st.binary(max_size=600) | st.text(max_size=600).map(str.encode))
def test_random_files_with_known_names(content: bytes) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("a.csv", "data_inert.txt", "trial.mat", "x.bin"):
            _load(Path(tmp), name, content)


@functools.cache
def _capture_bytes() -> bytes:
    """One capture, written once (its header holds the wall time, so every example mutates the same seed)."""
    with tempfile.TemporaryDirectory() as tmp:
        return _write_capture(Path(tmp) / "seed.mcap")


def _write_capture(path: Path) -> bytes:
    with CaptureWriter(path, flush_period_s=3600.0) as cap:
        tap = cap.add_unit(UnitHeader("foot", "openshoe", "openshoe-2015", "pty", "/dev/null"))
        for k in range(30):
            tap("rx", 1_000_000 * k, bytes(range(k, k + 40)))
            if k % 10 == 0:
                cap.flush()
    return path.read_bytes()


@FUZZ
@given(data=st.data())
def test_mutated_capture_reads_a_prefix_or_names_what_it_expected(data: st.DataObject) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        seed = _capture_bytes()
        path = Path(tmp) / "fuzzed.mcap"
        path.write_bytes(_mutate(data, seed, text=False))
        try:
            items = list(iter_capture(path))
        except InputFormatError as exc:
            assert "capture" in str(exc) or "MCAP" in str(exc) or "mcap" in str(exc)
            return
        assert len(items) <= 1 + 30 + 1
