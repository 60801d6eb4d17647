"""Captures that survive a bad byte: one flipped bit anywhere costs at most its own chunk, a damaged
header value is named (a default with a warning, or an error), a lost first chunk is a corrupt file.

The captures are written by the real writer during an emulated walk (``footnav demo`` on a
pseudo-terminal) and read back by the real reader and replay.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from footnav.app.commands.demo import DemoOptions, run_demo
from footnav.app.commands.live import LiveOptions, run_live
from footnav.app.commands.replay import ReplayOptions, run_replay
from footnav.app.config import defaults
from footnav.device.files.capture import (
    CaptureMessage,
    CaptureWriter,
    ReadState,
    UnitHeader,
    iter_capture,
    read_capture_info,
    summarize_capture,
)
from footnav.device.files.capture_header import json_path_at
from footnav.device.files.recordings import load_recording
from footnav.pipeline.errors import FootnavError, InputFormatError
from footnav.pipeline.nav_types import NavBatch, concat_batches
from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

SWEEP = 200


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, NavBatch]:
    """An 8 s emulated walk captured paced (many chunks of 0.1 s), and what the live session navigated."""
    tmp = tmp_path_factory.mktemp("walk")
    cfg = defaults()
    cfg.set("session.sessions_dir", str(tmp), "test")
    cfg.set("session.capture_flush_s", 0.1, "test: many chunks in a short capture")
    got: list[NavBatch] = []
    assert (
        run_demo(DemoOptions(duration_s=8.0, viewer=False, realtime=4.0, config=cfg, collect=lambda _: got.append)) == 0
    )
    (path,) = tmp.glob("*.mcap")
    return path, concat_batches(got)


def chunks(path: Path) -> list[tuple[int, int, int]]:
    """(start, end, messages) of each chunk record, by the mcap package's own reader."""
    out = []
    with open(path, "rb") as f:
        pos = 8
        for rec in StreamReader(f, emit_chunks=True).records:
            end = f.tell()
            if isinstance(rec, Chunk):
                n = sum(isinstance(r, Message) for r in breakup_chunk(rec, validate_crc=True))
                out.append((pos, end, n))
            pos = end
    return out


def messages(path: Path, state: ReadState | None = None) -> list[CaptureMessage]:
    return [m for m in iter_capture(path, state) if isinstance(m, CaptureMessage)]


def flipped(src: Path, dst: Path, bit: int) -> Path:
    data = bytearray(src.read_bytes())
    data[bit // 8] ^= 1 << (bit % 8)
    dst.write_bytes(bytes(data))
    return dst


def flip_in(src: Path, dst: Path, needle: bytes, offset: int, mask: int) -> Path:
    data = bytearray(src.read_bytes())
    data[data.index(needle) + offset] ^= mask
    dst.write_bytes(bytes(data))
    return dst


def replay(path: Path, **kw: object) -> NavBatch:
    got: list[NavBatch] = []
    opts = ReplayOptions(path=path, config=defaults(), viewer=False, collect=lambda _: got.append, **kw)  # type: ignore[arg-type]
    assert run_replay(opts) == 0
    return concat_batches(got)


def replay_cli(path: Path, timeout_s: float) -> subprocess.CompletedProcess[str]:
    """``footnav replay PATH --no-viewer`` in a process of its own."""
    return subprocess.run(
        [sys.executable, "-m", "footnav.app", "replay", str(path), "--no-viewer"],
        capture_output=True,
        text=True,
        check=False,
        timeout=timeout_s,
    )


def test_one_flipped_bit_anywhere_costs_at_most_its_own_chunk(walk: tuple[Path, NavBatch], tmp_path: Path) -> None:
    """A deterministic sweep of one flipped bit at 200 places spread over the file: every message
    outside the chunk holding the bit is read, in order; the skipped stretch is reported; a bit in the
    header or the first chunk is a named error, never a traceback."""
    path, _ = walk
    whole = messages(path)
    table = chunks(path)
    assert len(table) >= 8
    first_chunk = table[0]
    size = path.stat().st_size
    outcomes = {"intact": 0, "chunk lost": 0, "named error": 0, "header warning": 0}
    for k in range(SWEEP):
        byte = 8 + (size - 16) * k // SWEEP + k % 7  # spread, not aligned to any record
        bad = flipped(path, tmp_path / "bad.mcap", 8 * byte + k % 8)
        state = ReadState()
        try:
            got = messages(bad, state)
        except InputFormatError as exc:
            assert str(bad) in str(exc) and "expected" in str(exc)
            assert byte < first_chunk[1], (byte, exc)  # only the header and the first chunk are fatal
            outcomes["named error"] += 1
            continue
        hit = [c for c in table if c[0] <= byte < c[1]]
        if hit and len(got) == len(whole):
            # a bit in a chunk header field the reader does not rely on (its time range, the sizes it checks the
            # CRC-verified payload against): every message read, unchanged
            assert [(m.foot, m.direction, m.host_ns, m.data) for m in got] == [
                (m.foot, m.direction, m.host_ns, m.data) for m in whole
            ], byte
            assert not state.gaps, (byte, state.gaps)
            outcomes["intact"] += 1
        elif hit:
            start, end, n = hit[0]
            assert len(got) == len(whole) - n, (byte, hit)
            assert [(g.start, g.end) for g in state.gaps] == [(start, end)], (byte, state.gaps)
            lost = {(m.host_ns, m.direction) for m in whole} - {(m.host_ns, m.direction) for m in got}
            assert len(lost) == n or n == 0
            outcomes["chunk lost"] += 1
        else:
            assert [(m.foot, m.direction, m.host_ns, m.data) for m in got] == [
                (m.foot, m.direction, m.host_ns, m.data) for m in whole
            ], byte
            assert not state.gaps and not state.truncated
            info = read_capture_info(bad)
            outcomes["header warning" if info.warnings else "intact"] += 1
    assert outcomes["chunk lost"] >= 0.8 * SWEEP, outcomes
    assert outcomes["named error"] >= 1, outcomes


def test_a_flipped_bit_in_a_chunks_opcode_loses_nothing(walk: tuple[Path, NavBatch], tmp_path: Path) -> None:
    """Each of the 8 bits of a chunk record's opcode byte: the record then names another kind (0x07, a message
    index, among them), which the reader used to skip with its messages and no gap. Its fields and CRC are a
    chunk's, so it is read whole: every message, no gap, its offset kept as repaired."""
    path, _ = walk
    whole = [(m.foot, m.direction, m.host_ns, m.data) for m in messages(path)]
    start = chunks(path)[3][0]
    for bit in range(8):
        state = ReadState()
        got = messages(flipped(path, tmp_path / "bad.mcap", 8 * start + bit), state)
        assert [(m.foot, m.direction, m.host_ns, m.data) for m in got] == whole, bit
        assert not state.gaps and state.repaired == [start], (bit, state.gaps, state.repaired)
    state = ReadState()
    assert messages(path, state) and state.repaired == []  # an intact file: nothing repaired


@pytest.mark.parametrize("where", [0.3, 0.6, 0.97])
def test_replay_resumes_at_the_next_intact_chunk_and_reports_the_gap(
    walk: tuple[Path, NavBatch], tmp_path: Path, capsys: pytest.CaptureFixture[str], where: float
) -> None:
    path, live = walk
    table = chunks(path)
    start, end, _ = table[int(where * (len(table) - 1))]
    bad = flipped(path, tmp_path / "bad.mcap", 8 * ((start + end) // 2) + 3)
    got = replay(bad)
    err = capsys.readouterr().err
    lost = len(live) - len(got)
    assert 0 < lost < len(live) // 4, lost
    # the stretch is reported with the time the stream went without data, or, when the unit sent no
    # data after it (the last chunks may hold only events), as the end of this unit's data
    whole_rx = [m.host_ns for m in messages(path) if m.direction == "rx"]
    kept_rx = {m.host_ns for m in messages(bad) if m.direction == "rx"}
    last_lost_ns = max(t for t in whole_rx if t not in kept_rx)
    after = "no data for" if any(t > last_lost_ns for t in kept_rx) else "nothing of this unit comes after them"
    assert f"bytes {start}-{end} of {bad.stat().st_size} are damaged and were skipped; {after}" in err
    assert f"1 damaged stretch(es) skipped: {lost} samples lost ({len(got)} of the {len(live)}" in err
    # every sample before the damaged chunk is the live session's, bit for bit; after it, the same
    # samples of the unit's clock as live, to the last one
    differ = np.flatnonzero(got.t_s != live.t_s[: len(got)])
    k = int(differ[0]) if differ.size else len(got)
    assert 0 < k < len(got) or where > 0.9
    np.testing.assert_array_equal(got.pos_n_m[:k], live.pos_n_m[:k])
    np.testing.assert_array_equal(got.t_s[k:], live.t_s[len(live) - (len(got) - k) :])


def test_the_command_line_replays_a_damaged_capture_without_a_traceback(
    walk: tuple[Path, NavBatch], tmp_path: Path
) -> None:
    path, live = walk
    start, end, _ = chunks(path)[3]
    bad = flipped(path, tmp_path / "bad.mcap", 8 * (start + 200))
    proc = replay_cli(bad, timeout_s=300)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert f"bytes {start}-{end}" in proc.stderr and "samples lost" in proc.stderr
    assert f"of the {len(live)} the live session navigated" in proc.stderr


def test_a_corrupt_first_chunk_is_a_corrupt_file(walk: tuple[Path, NavBatch], tmp_path: Path) -> None:
    path, _ = walk
    start, end, _ = chunks(path)[0]
    bad = flipped(path, tmp_path / "first.mcap", 8 * (end - 20))
    for read in (summarize_capture, read_capture_info, replay):
        with pytest.raises(InputFormatError) as err:
            read(bad)
        text = str(err.value)
        assert f"{bad} is corrupt: bytes {start} to {end}, before its first message" in text
        assert "expected a footnav capture whose header and first chunk are intact" in text
        assert "no answer" not in text
    proc = replay_cli(bad, timeout_s=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "100 %" not in proc.stderr
    assert "is corrupt" in proc.stderr


def test_header_values_carry_a_checksum(
    walk: tuple[Path, NavBatch], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each damaged header value is named: replaced by its default with a warning where the replay can
    do without it, an error where it decides how the bytes are read."""
    path, live = walk
    info = read_capture_info(path)
    assert not info.warnings
    offset = info.session["monotonic_to_unix_ns"]

    # "rate_hz": 1000.0 -> q000.0 (the settings no longer parse): the default, with a warning
    bad = flip_in(path, tmp_path / "rate.mcap", b'"rate_hz": 1000', 11, 0x40)
    got = read_capture_info(bad)
    assert "rate_hz" not in got.units[0].settings and got.units[0].settings["mode"] == "normal_imu"
    assert got.units[0].settings["nav_config"] == info.units[0].settings["nav_config"]
    (warning,) = got.warnings
    assert "unit 'foot': settings.rate_hz fails the header's CRC-32 check" in warning and "q000.0" in warning
    assert "1000 Hz" in warning
    assert len(replay(bad)) == len(live)
    assert "settings.rate_hz fails" in capsys.readouterr().err

    # a digit of the clock offset flipped to another digit (the schema cannot see it): recovered
    bad = flip_in(path, tmp_path / "offset.mcap", offset.encode(), 4, 0x01)
    got = read_capture_info(bad)
    assert got.session["monotonic_to_unix_ns"] == offset
    assert "session: monotonic_to_unix_ns fails the header's CRC-32 check" in got.warnings[0]

    # a navigator setting: the configuration in force, with a warning naming the key
    bad = flip_in(path, tmp_path / "threshold.mcap", b'"threshold": 25', 14, 0x02)
    got = read_capture_info(bad)
    assert "nav_config" not in got.units[0].settings
    assert "settings.nav_config.detector.threshold fails" in got.warnings[0]

    # the output mode decides how the bytes are decoded: an error naming it
    bad = flip_in(path, tmp_path / "mode.mcap", b'"mode": "normal', 10, 0x02)
    with pytest.raises(InputFormatError, match=r"unit 'foot': settings\.mode fails the header's CRC-32 check"):
        read_capture_info(bad)

    # a length inside the record: the record no longer parses, the checksum still finds the bit
    bad = flip_in(path, tmp_path / "length.mcap", b"\x04\x00\x00\x00port", 0, 0x10)
    got = read_capture_info(bad)
    assert got.units[0].settings == info.units[0].settings and "port fails" in got.warnings[0]

    # the checksum entry itself
    bad = flip_in(path, tmp_path / "crc.mcap", b"crc32\x08\x00\x00\x00", 10, 0x01)
    got = read_capture_info(bad)
    assert got.units == info.units or got.session != info.session
    assert any("checksum entry is itself damaged" in w for w in got.warnings)


def test_captures_without_header_checksums_still_replay(tmp_path: Path) -> None:
    """A capture written before the checksum (no ``crc32`` entry) is read by the schema alone."""
    from mcap.writer import CompressionType, Writer

    path = tmp_path / "old.mcap"
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="footnav", library="footnav 0.0.9")
        w.add_metadata("footnav.session", {"format_version": "1", "monotonic_to_unix_ns": "1000"})
        unit = UnitHeader("foot", "u", "openshoe-2015", "serial", "/dev/x", {"rate_hz": 500.0})
        w.add_metadata("footnav.unit", unit.to_metadata())
        ch = w.register_channel("foot/rx", "application/octet-stream", 0)
        w.add_message(ch, 1005, b"\x01\x02", 5)
        w.finish()
    info = read_capture_info(path)
    assert info.units[0].settings == {"rate_hz": 500.0} and not info.warnings
    assert [m.data for m in messages(path)] == [b"\x01\x02"]
    bad = flip_in(path, tmp_path / "old-bad.mcap", b'"rate_hz": 500', 11, 0x40)
    with pytest.raises(InputFormatError, match="unit 'foot': settings is"):
        read_capture_info(bad)  # the existing schema check names it


def test_json_path_at_names_the_innermost_key() -> None:
    text = '{"a": 1, "nav": {"det": {"threshold": 25.0, "kind": "shoe"}}, "v": [1, 2]}'
    assert json_path_at(text, text.index("25.0") + 1) == "nav.det.threshold"
    assert json_path_at(text, text.index("threshold")) == "nav.det.threshold"
    assert json_path_at(text, text.index("shoe")) == "nav.det.kind"
    assert json_path_at(text, text.index("2]")) == "v.1"
    assert json_path_at(text, 0) == ""


def test_two_units_of_one_foot_name_are_refused(tmp_path: Path) -> None:
    with CaptureWriter(tmp_path / "two.mcap") as w:
        w.add_unit(UnitHeader("left", "u", "s", "serial", "/dev/a"))
        with pytest.raises(ValueError, match="two units named 'left'"):
            w.add_unit(UnitHeader("left", "u", "s", "serial", "/dev/b"))
    # a file that declares two (written by hand, as another writer might)
    from mcap.writer import Writer

    path = tmp_path / "dup.mcap"
    with open(path, "wb") as f:
        mw = Writer(f)
        mw.start(profile="footnav", library="x")
        mw.add_metadata("footnav.session", {"format_version": "1"})
        for port in ("/dev/a", "/dev/b"):
            mw.add_metadata("footnav.unit", UnitHeader("left", "u", "s", "serial", port).to_metadata())
        mw.finish()
    with pytest.raises(InputFormatError, match="two units are named 'left'"):
        read_capture_info(path)
    # footnav live refuses one unit for two feet before opening anything
    opts = LiveOptions(ports={"left": "/dev/null", "right": "/dev/null"}, config=defaults(), viewer=False)
    with pytest.raises(FootnavError, match=r"one unit \(/dev/null\) is given for two feet"):
        run_live(opts)


@pytest.mark.parametrize("bad", ["nan", "NaN", "inf"])
def test_a_csv_whose_first_time_stamp_is_not_a_number_is_refused(tmp_path: Path, bad: str) -> None:
    """A bad first time stamp is named like any other (before: 10 000 rows exported with t = NaN)."""
    t = [bad] + [f"{k / 100:.2f}" for k in range(1, 10_000)]
    path = tmp_path / "walk.csv"
    path.write_text("t,ax,ay,az,gx,gy,gz\n" + "".join(f"{x},0,0,9.81,0,0,0\n" for x in t))
    with pytest.raises(InputFormatError, match=r"time stamp \S+ at data row 1 \(1 not finite\)"):
        load_recording(path)
    out = tmp_path / "track.csv"
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.app", "export", str(path), "-o", str(out)],
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    assert proc.returncode == 2 and "data row 1" in proc.stderr and not out.exists()
