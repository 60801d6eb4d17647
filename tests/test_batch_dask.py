"""Folders on a Dask cluster (``--scheduler``, ``footnav.app.batch(client=)``) and tracks as Parquet: a real
``distributed.LocalCluster`` of two worker processes on loopback, real recordings of ``../shared/data``; every
result the serial run's, the Parquet values the CSV's."""

from __future__ import annotations

import csv
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path

import dask
import pyarrow.parquet as pq
import pytest
from distributed import Client, LocalCluster
from footnav.app import batch, navigate, read_recording
from footnav.app.cli import main
from footnav.app.commands import batch as batch_module
from footnav.app.commands.batch import run_files
from footnav.app.commands.export import COLUMN_UNITS
from footnav.pipeline.errors import FootnavError

from tests.conftest import FOLDER_TRIALS

TRIALS = FOLDER_TRIALS


@pytest.fixture(scope="module")
def cluster() -> Iterator[LocalCluster]:
    """Two single-threaded worker processes and their scheduler, on 127.0.0.1, for the whole module."""
    # a task whose worker dies is given up after two tries (default four): test_a_file_that_kills_its_worker
    with (
        dask.config.set({"distributed.scheduler.allowed-failures": 1}),
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
        ) as local,
    ):
        yield local


@pytest.fixture(scope="module")
def client(cluster: LocalCluster) -> Iterator[Client]:
    with Client(cluster.scheduler_address, set_as_default=False) as c:
        yield c


@pytest.fixture(scope="module")
def folder(recordings_folder: Path) -> Path:
    return recordings_folder


def _footnav(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """``footnav ARGS`` in this process: exit status, stdout, stderr."""
    capsys.readouterr()
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_evaluate_on_the_cluster_prints_the_serial_table(
    cluster: LocalCluster, folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    serial = _footnav(capsys, "evaluate", str(folder), "--jobs", "1")
    dask = _footnav(capsys, "evaluate", str(folder), "--scheduler", cluster.scheduler_address)
    assert serial[0] == 0, serial[2]
    assert "ground truth (3 files)" in serial[1] and "closed loops (1 files)" in serial[1]
    assert dask == serial


def test_export_on_the_cluster_writes_the_serial_runs_bytes(
    cluster: LocalCluster, folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    serial = _footnav(capsys, "export", str(folder), "-o", str(tmp_path / "serial"), "--jobs", "1")
    dask = _footnav(
        capsys, "export", str(folder), "-o", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address
    )
    assert serial[0] == 0 and dask[0] == 0, serial[2] + dask[2]
    one, two = _tree(tmp_path / "serial"), _tree(tmp_path / "dask")
    assert sorted(one) == sorted(
        [f"{Path(n).stem}.csv" for n in TRIALS[:2]] + [f"vicon/{Path(TRIALS[2]).stem}.csv", "short_walk.csv"]
    )
    assert one == two
    assert dask[1].replace("dask", "serial") == serial[1]
    assert serial[1].splitlines()[-1] == "exported 4 of 4 files"


def test_a_failing_file_on_the_cluster_is_reported_and_the_others_go_on(
    cluster: LocalCluster, folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    broken = tmp_path / "in"
    shutil.copytree(folder, broken)
    (broken / "zz-broken.mat").write_bytes(b"MATLAB 5.0 MAT-file, not really")
    code, out, err = _footnav(
        capsys, "export", str(broken), "-o", str(tmp_path / "out"), "--scheduler", cluster.scheduler_address
    )
    assert code == 2
    assert out.splitlines()[-1] == "exported 4 of 5 files, 1 failed"
    assert "footnav: failed:" in err and "zz-broken.mat" in err and "Traceback" not in err
    assert len(list((tmp_path / "out").rglob("*.csv"))) == 4
    code, out, err = _footnav(capsys, "evaluate", str(broken), "--scheduler", cluster.scheduler_address)
    assert code == 2 and "footnav: skipped:" in err and "zz-broken.mat" in err
    assert "ground truth (3 files)" in out


def test_the_api_on_the_cluster_returns_the_serial_results(client: Client, folder: Path) -> None:
    serial = batch(folder, jobs=1)
    dask = batch(folder, client=client)
    assert [r.path for r in dask] == [r.path for r in serial]
    names = [r.value.name for r in dask if r.value is not None]
    assert names == ["2017-11-27-11-12-44", "2017-12-15-18-01-18", "short_walk", "2018-02-22-10-09-36"]
    # repr: every float exactly (NaN fields make == of the dataclasses false even for equal runs)
    assert [repr(r.value) for r in dask] == [repr(r.value) for r in serial]
    assert all(r.error == "" for r in dask)


def test_parquet_export_on_the_cluster_holds_the_csv_values(client: Client, folder: Path, tmp_path: Path) -> None:
    csvs = batch(folder, "export", out_dir=tmp_path / "csv", jobs=1)
    on_cluster = batch(folder, "export", out_dir=tmp_path / "pq", client=client, output_format="parquet")
    batch(folder, "export", out_dir=tmp_path / "pq1", jobs=1, output_format="parquet")
    assert [r.error for r in csvs + on_cluster] == [""] * 8
    assert _tree(tmp_path / "pq") == _tree(tmp_path / "pq1")  # the same bytes wherever written
    tracks = sorted((tmp_path / "pq").rglob("*.parquet"))
    assert len(tracks) == 4
    for track in tracks:
        rel = track.relative_to(tmp_path / "pq").with_suffix(".csv")
        _assert_parquet_holds_the_csv(track, tmp_path / "csv" / rel)


def _assert_parquet_holds_the_csv(parquet: Path, csv_path: Path) -> None:
    """Every value of the Parquet file, formatted as the CSV writer formats it, is the CSV's text."""
    table = pq.read_table(parquet)
    with csv_path.open(newline="") as f:
        rows = list(csv.reader(f))
    assert table.column_names == rows[0]
    assert table.num_rows == len(rows) - 1 > 1000
    for i, name in enumerate(rows[0]):
        values = table.column(name).to_pylist()
        text = [str(int(v)) if name == "stance" else f"{v:.9g}" for v in values]
        assert text == [row[i] for row in rows[1:]], name
    schema = pq.read_schema(parquet)
    assert schema.field("stance").type == "bool" and schema.field("x").type == "double"
    assert {n: schema.field(n).metadata[b"unit"].decode() for n in rows[0]} == {n: COLUMN_UNITS[n] for n in rows[0]}


def test_one_recording_to_parquet_by_its_name(folder: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    source = str(folder / TRIALS[0])
    assert _footnav(capsys, "export", source, "-o", str(tmp_path / "t.parquet"))[0] == 0
    assert _footnav(capsys, "export", source, "-o", str(tmp_path / "t.csv"))[0] == 0
    assert _footnav(capsys, "export", source, "-o", str(tmp_path / "t"), "--output-format", "parquet")[0] == 0
    assert (tmp_path / "t").read_bytes() == (tmp_path / "t.parquet").read_bytes()
    _assert_parquet_holds_the_csv(tmp_path / "t.parquet", tmp_path / "t.csv")
    navigate(read_recording(source)).to_parquet(tmp_path / "api.parquet")  # the API's, the same bytes
    assert (tmp_path / "api.parquet").read_bytes() == (tmp_path / "t.parquet").read_bytes()
    code, _, err = _footnav(capsys, "export", source, "-o", str(tmp_path / "u.csv"), "--output-format", "parquet")
    assert code == 2 and "is named .csv but --output-format is parquet" in err
    assert not (tmp_path / "u.csv").exists()


def test_jobs_and_scheduler_together_are_refused(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["evaluate", "x", "--jobs", "2", "--scheduler", "tcp://127.0.0.1:8786"])
    assert exit_.value.code == 2
    assert "--scheduler: not allowed with argument --jobs" in capsys.readouterr().err


def test_an_unreachable_scheduler_is_a_footnav_error(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setattr(batch_module, "SCHEDULER_TIMEOUT_S", 1.0)
    with pytest.raises(FootnavError, match=r"cannot reach the Dask scheduler at tcp://127\.0\.0\.1:9"):
        batch_module.connect("tcp://127.0.0.1:9")


def test_without_the_extras_the_errors_name_them(monkeypatch: pytest.MonkeyPatch, folder: Path, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(FootnavError, match=r"pip install 'footnav\[dask\]'"):
        batch_module.connect("tcp://127.0.0.1:8786")
    monkeypatch.setitem(sys.modules, "pyarrow", None)
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    with pytest.raises(ImportError, match=r"pip install 'footnav\[parquet\]'"):  # a FootnavError too, before any work
        batch(folder / TRIALS[0], "export", out_dir=tmp_path, jobs=1, output_format="parquet")
    assert not list(tmp_path.iterdir())
    assert main(["export", str(folder / TRIALS[0]), "-o", str(tmp_path / "t.parquet")]) == 2


def _exits_on_a(path: Path) -> str:
    """A task that ends its worker process for the file ``a`` (``SystemExit`` passes ``_guarded``)."""
    if path.name == "a":
        sys.exit(3)
    return path.name.upper()


def test_a_file_that_kills_its_worker_is_that_files_failure(client: Client) -> None:
    (killed,) = run_files(_exits_on_a, [Path("a")], client=client)
    assert killed.value is None and killed.error.startswith("a: on the Dask cluster: KilledWorker:"), killed.error
    # the nannies restart the workers, and the cluster runs the next files
    assert [r.value for r in run_files(_exits_on_a, [Path("b"), Path("c")], client=client)] == ["B", "C"]
