"""``footnav export DIR -o OUTDIR`` and ``footnav evaluate DIR`` over a folder, serially and on a process pool
(``footnav.app.commands.batch``): the same files, the same bytes, the same table; failures per file."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from footnav.app.commands.batch import export_destinations, run_files
from footnav.pipeline.errors import FootnavError

from tests.conftest import FOLDER_TRIALS

TRIALS = FOLDER_TRIALS


def _footnav(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "footnav.app", *args], capture_output=True, text=True, timeout=600, check=False
    )


@pytest.fixture(scope="module")
def folder(recordings_folder: Path) -> Path:
    return recordings_folder


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_export_of_a_folder_on_two_processes_writes_the_serial_runs_bytes(folder: Path, tmp_path: Path) -> None:
    serial = _footnav("export", str(folder), "-o", str(tmp_path / "serial"), "--jobs", "1")
    pooled = _footnav("export", str(folder), "-o", str(tmp_path / "pooled"), "--jobs", "2")
    assert serial.returncode == 0 and pooled.returncode == 0, serial.stderr + pooled.stderr
    one, two = _tree(tmp_path / "serial"), _tree(tmp_path / "pooled")
    assert sorted(one) == sorted(
        [f"{Path(n).stem}.csv" for n in TRIALS[:2]] + [f"vicon/{Path(TRIALS[2]).stem}.csv", "short_walk.csv"]
    )
    assert one == two
    # one summary line per file, in the files' order, the same in both runs but for the folder's name
    lines = serial.stdout.splitlines()
    assert len(lines) == 5 and lines[-1] == "exported 4 of 4 files"
    assert pooled.stdout.replace("pooled", "serial") == serial.stdout


def test_a_folders_tracks_are_each_files_single_export(folder: Path, tmp_path: Path) -> None:
    single = _footnav("export", str(folder / "vicon" / TRIALS[2]), "-o", str(tmp_path / "one.csv"))
    batch = _footnav("export", str(folder / "vicon"), "-o", str(tmp_path / "out"), "--jobs", "2")
    assert single.returncode == 0 and batch.returncode == 0, single.stderr + batch.stderr
    assert (tmp_path / "out" / f"{Path(TRIALS[2]).stem}.csv").read_bytes() == (tmp_path / "one.csv").read_bytes()


def test_evaluate_on_two_processes_prints_the_serial_table(folder: Path) -> None:
    serial = _footnav("evaluate", str(folder), "--jobs", "1")
    pooled = _footnav("evaluate", str(folder), "--jobs", "2")
    assert serial.returncode == 0, serial.stderr
    assert "ground truth (3 files)" in serial.stdout and "closed loops (1 files)" in serial.stdout
    assert pooled.returncode == 0 and pooled.stdout == serial.stdout


def test_a_failing_file_is_reported_and_the_others_go_on(folder: Path, tmp_path: Path) -> None:
    broken = tmp_path / "in"
    shutil.copytree(folder, broken)
    (broken / "zz-broken.mat").write_bytes(b"MATLAB 5.0 MAT-file, not really")
    proc = _footnav("export", str(broken), "-o", str(tmp_path / "out"), "--jobs", "2")
    assert proc.returncode == 2
    assert "exported 4 of 5 files, 1 failed" in proc.stdout
    assert "footnav: failed:" in proc.stderr and "zz-broken.mat" in proc.stderr and "Traceback" not in proc.stderr
    assert len(list((tmp_path / "out").rglob("*.csv"))) == 4
    evaluated = _footnav("evaluate", str(broken), "--jobs", "2")
    assert evaluated.returncode == 2 and "zz-broken.mat" in evaluated.stderr
    assert "ground truth (3 files)" in evaluated.stdout


def _fails_on_b(path: Path) -> str:
    if path.name == "b":
        raise ValueError("not this one")
    return path.name.upper()


def test_run_files_keeps_the_order_and_turns_errors_into_lines() -> None:
    files = [Path("a"), Path("b"), Path("c")]
    for jobs in (1, 2):
        results = run_files(_fails_on_b, files, jobs)
        assert [r.value for r in results] == ["A", None, "C"]
        assert results[1].error == "b: ValueError: not this one"


class _SaysWhenTornDown:
    def __init__(self, path: Path) -> None:
        self.path = path

    def __del__(self) -> None:
        self.path.write_text("torn down")


_KEPT: list[_SaysWhenTornDown] = []


def _keeps_an_object(path: Path) -> str:
    """A task that leaves the worker an object, which writes ``<path>.torn`` when the interpreter tears it down."""
    _KEPT.append(_SaysWhenTornDown(path.with_suffix(".torn")))
    return path.name


def test_the_pools_workers_end_without_the_interpreters_teardown(tmp_path: Path) -> None:
    files = [tmp_path / "a", tmp_path / "b", tmp_path / "c"]
    results = run_files(_keeps_an_object, files, 2)
    assert [r.value for r in results] == ["a", "b", "c"]  # every result arrived
    assert not list(tmp_path.glob("*.torn"))


def test_two_files_of_one_name_are_refused(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    files = [tmp_path / "a" / "walk.mat", tmp_path / "walk.csv"]
    with pytest.raises(FootnavError, match="would both be exported"):
        export_destinations(files, files, tmp_path / "out")


def test_steps_with_a_folder_is_an_error(folder: Path, tmp_path: Path) -> None:
    proc = _footnav("export", str(folder), "-o", str(tmp_path / "out"), "--steps", str(tmp_path / "s.csv"))
    assert proc.returncode == 2 and "--steps: for one recording" in proc.stderr
