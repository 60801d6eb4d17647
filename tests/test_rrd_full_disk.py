"""Issue 30: a .rrd file that cannot be written to its end (a full disk) is said at once in one line,
the session and its capture go on, the exit code is 3, and the part written reads back with the readers
the documentation names (``RrdReader(...).stream()``, ``rerun rrd stats``).

The full disk is a 4 MB tmpfs mounted in a user and mount namespace of the footnav process
(``unshare -rm``), the way CI runs (root, ``.ci/run``); the capture is written elsewhere.
"""

from __future__ import annotations

import collections
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from footnav.device.files.capture import summarize_capture
from footnav.views.sinks import RRD_STREAM_HEADER_BYTES, trim_rrd
from rerun.chunk import RrdReader

RERUN = Path(sys.executable).with_name("rerun")
pytestmark = pytest.mark.filterwarnings("ignore:RRD file has no footer")  # a file cut short has none


def _rows(path: Path) -> collections.Counter[str]:
    """Temporal rows per entity, read as the sharing guide says (``RrdReader(path).stream()``)."""
    rows: collections.Counter[str] = collections.Counter()
    for chunk in RrdReader(path).stream():
        if not chunk.is_static:
            rows[chunk.entity_path] += chunk.num_rows
    return rows


def _write_rrd(path: Path, flushes: int) -> None:
    """A real .rrd: ``flushes`` messages of 1000 scalars each on ``/x``."""
    rec = rr.RecordingStream("footnav", recording_id="trim-test")
    rec.set_sinks(rr.FileSink(str(path), write_footer=False))
    for i in range(flushes):
        t = np.arange(i * 1000, (i + 1) * 1000) / 1000.0
        rec.send_columns("x", indexes=[rr.TimeColumn("t", duration=t)], columns=rr.Scalars.columns(scalars=t))
        rec.flush(timeout_sec=10)
    rec.disconnect()


def test_a_file_cut_mid_message_is_trimmed_to_its_last_whole_message(tmp_path: Path) -> None:
    path = tmp_path / "cut.rrd"
    _write_rrd(path, 5)
    whole = path.stat().st_size
    assert trim_rrd(path) == whole and path.stat().st_size == whole  # a whole file is left as it is
    assert _rows(path)["/x"] == 5000
    with open(path, "r+b") as f:
        f.truncate(whole - 100)  # as a full disk leaves it: the last message half written
    with pytest.raises(RuntimeError, match="exceeds file size"):
        _rows(path)
    kept = trim_rrd(path)
    assert RRD_STREAM_HEADER_BYTES < kept < whole - 100 and path.stat().st_size == kept
    assert _rows(path)["/x"] == 4000  # every whole message before the cut
    assert trim_rrd(tmp_path / "missing.rrd") == 0


@pytest.fixture(scope="module")
def full_disk_demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess[str], Path, Path]:
    """``footnav demo --save`` onto a 4 MB tmpfs (a 60-s walk's .rrd is about 15 MB)."""
    if shutil.which("unshare") is None:
        pytest.skip("no unshare on this machine: the full disk is a tmpfs in a mount namespace")
    tmp = tmp_path_factory.mktemp("full-disk")
    disk, out, sessions = tmp / "disk", tmp / "out", tmp / "sessions"
    for folder in (disk, out, sessions):
        folder.mkdir()
    footnav = [sys.executable, "-m", "footnav.app", "demo", "--duration", "60", "--pace", "max", "--no-viewer"]
    script = (
        f'mount -t tmpfs -o size=4m tmpfs "{disk}" || exit 97; "$@" --save "{disk}/walk.rrd" '
        f'--sessions "{sessions}"; code=$?; cp "{disk}/walk.rrd" "{out}/walk.rrd"; exit $code'
    )
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run(
        ["unshare", "-rm", "sh", "-c", script, "sh", *footnav],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
        check=False,
    )
    assert proc.returncode != 97, f"mounting a tmpfs in a user namespace failed: {proc.stderr}"
    (capture,) = sessions.glob("*.mcap")
    return proc, out / "walk.rrd", capture


def test_a_full_disk_is_said_in_one_line_and_the_session_goes_on(
    full_disk_demo: tuple[subprocess.CompletedProcess[str], Path, Path],
) -> None:
    proc, rrd, capture = full_disk_demo
    assert proc.returncode == 3, proc.stderr  # the session ran; its recording file is incomplete
    assert "Traceback" not in proc.stderr and "File-writer thread" not in proc.stderr
    said = [line for line in proc.stderr.splitlines() if str(rrd.name) in line and "stopped" in line]
    assert len(said) == 1, proc.stderr
    assert "no space left on its disk" in said[0] and "readable" in said[0] and "carry on" in said[0]
    assert [ln for ln in proc.stderr.splitlines() if "ERROR" in ln or "WARN" in ln] == []  # no SDK log lines
    assert "samples navigated: 60000 of 60000" in proc.stdout  # the walk went on to its end
    summary = summarize_capture(capture)  # and so did the capture, on its own disk
    assert [e["samples"] for e in summary.events["foot"] if e.get("event") == "end"] == [60_000]


def test_the_part_written_reads_back_with_the_documented_readers(
    full_disk_demo: tuple[subprocess.CompletedProcess[str], Path, Path],
) -> None:
    _, rrd, _ = full_disk_demo
    assert 3_000_000 < rrd.stat().st_size <= 4 * 1024 * 1024
    rows = _rows(rrd)
    assert rows["/world/truth/foot"] == 60_000  # logged first, whole
    assert 1000 < rows["/world/foot/track"] < 60_000  # the walk up to where the disk filled
    stats = subprocess.run([str(RERUN), "rrd", "stats", str(rrd)], capture_output=True, text=True, check=False)
    assert stats.returncode == 0, stats.stderr
    assert "num_chunks" in stats.stdout
