"""Fuzzing the loaders, the capture reader and the navigator behind them (hypothesis).

Every input either loads into consistent arrays or is refused with an ``InputFormatError`` that a
person can read; whatever loads navigates without an exception other than ``FootnavError`` and
without leaving non-finite or runaway estimates unflagged. Seeds are real files from ``../shared/data``
(their first lines) and valid files written here, mutated byte- and line-wise.

Briefly in the suite; at length on demand::

    FOOTNAV_FUZZ_EXAMPLES=20000 .venv/bin/python -m pytest tests/test_fuzz_inputs.py tests/test_decoders.py
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import os
import tempfile
from collections.abc import Callable
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


# ------------------------------------------------------------------ capture metadata (the header's settings)


def rewrite_capture(src: Path, dst: Path, edit: Callable[[str, dict[str, str]], dict[str, str]]) -> None:
    """Copy the capture ``src`` to ``dst`` record by record, each metadata record (``footnav.session``,
    ``footnav.unit``) replaced by ``edit(name, metadata)``; the data is unchanged."""
    from mcap.records import Channel, Header, Message, Metadata
    from mcap.stream_reader import StreamReader
    from mcap.writer import Writer

    channels: dict[int, int] = {}
    with src.open("rb") as f, dst.open("wb") as out:
        writer = Writer(out)
        for rec in StreamReader(f).records:
            if isinstance(rec, Header):
                writer.start(profile=rec.profile, library=rec.library)
            elif isinstance(rec, Metadata):
                writer.add_metadata(rec.name, edit(rec.name, dict(rec.metadata)))
            elif isinstance(rec, Channel):
                channels[rec.id] = writer.register_channel(rec.topic, rec.message_encoding, 0, dict(rec.metadata))
            elif isinstance(rec, Message):
                writer.add_message(channels[rec.channel_id], rec.log_time, rec.data, rec.publish_time, rec.sequence)
        writer.finish()


@functools.cache
def demo_capture() -> bytes:
    """A real capture: a 3-s demo walk through the emulated unit, the serial path and the pipeline."""
    from footnav.app.cli import main

    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(io.StringIO()):
        with contextlib.redirect_stderr(io.StringIO()) as err:
            code = main(["demo", "--duration", "3", "--pace", "max", "--no-viewer", "--sessions", tmp])
        assert code == 0, err.getvalue()
        (path,) = Path(tmp).glob("*.mcap")
        return path.read_bytes()


ANY_JSON = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**70), 2**70)
    | st.sampled_from([0, 1, -1, 15, 16, 2**31, 14, 1000])
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=12)
    | st.sampled_from(["normal_imu", "dual_imu_raw", "raw_imu_fused", "calibration_raw_imu", "ins", "steps", "or"]),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=8,
)
"""Values of every JSON type, and the names and numbers the settings really hold."""
EXTRA_SETTINGS = ("dual_imu_lever_b_m", "fused_imu_mask", "imu_mask", "model", "ins_state_ids")
"""Settings a demo capture does not record but others do (dual-IMU board, raw IMUs, calibration, models)."""


def _settings_paths(settings: dict[str, object], prefix: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every key of the settings, nested ones (``nav_config.filter.align_s``) included."""
    paths = []
    for key, value in settings.items():
        paths.append((*prefix, key))
        if isinstance(value, dict):
            paths.extend(_settings_paths(value, (*prefix, key)))
    return paths


def _cli(*args: str) -> tuple[int, str]:
    """Run the command line in this process; (exit code, stderr). An exception other than the exits
    the CLI makes itself fails the test, with its traceback."""
    from footnav.app.cli import main

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
        try:
            code = main(list(args))
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 2
    return code, err.getvalue()


@FUZZ
@given(data=st.data())
def test_mutated_capture_settings_replay_or_say_which_value_is_wrong(data: st.DataObject) -> None:
    """Every recorded setting, nested navigator settings too, the foot name and the session record,
    replaced by a value of another type or out of range: replay and export work, or refuse the capture
    in one line; never a traceback."""
    seed = demo_capture()
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "seed.mcap", Path(tmp) / "mutated.mcap"
        src.write_bytes(seed)
        target = data.draw(st.sampled_from(["settings", "session", "foot"]), label="target")
        value = data.draw(ANY_JSON, label="value")

        def edit(name: str, md: dict[str, str]) -> dict[str, str]:
            if name == "footnav.session" and target == "session":
                key = data.draw(st.sampled_from(sorted(md)), label="session key")
                return {**md, key: data.draw(st.text(max_size=24) | st.just(str(value)), label="session value")}
            if name != "footnav.unit" or target == "session":
                return md
            if target == "foot":
                return {**md, "foot": data.draw(st.text(max_size=12) | st.just("../../../x"), label="foot")}
            settings = json.loads(md["settings"])
            paths = _settings_paths(settings) + [(k,) for k in EXTRA_SETTINGS]
            path = data.draw(st.sampled_from(paths), label="setting")
            table = settings
            for key in path[:-1]:
                table = table[key]
            table[path[-1]] = value
            return {**md, "settings": json.dumps(settings)}

        rewrite_capture(src, dst, edit)
        if data.draw(st.booleans(), label="replay"):
            code, err = _cli("replay", str(dst), "--no-viewer")
        else:
            code, err = _cli("export", str(dst), "-o", str(Path(tmp) / "track.csv"))
        assert "Traceback" not in err
        assert code in (0, 2), err
        if code == 2:
            assert len([line for line in err.splitlines() if line.startswith("footnav: error:")]) == 1, err
        assert sorted(p.name for p in Path(tmp).iterdir()) <= ["mutated.mcap", "seed.mcap", "track.csv"]
