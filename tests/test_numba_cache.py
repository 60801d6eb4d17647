"""The compiled kernels' on-disk cache is keyed by every source below ``pipeline/``, subfolders
included (``footnav.pipeline.sources_digest``)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import footnav.pipeline
from footnav.pipeline import sources_digest

PIPELINE = Path(footnav.pipeline.__file__).resolve().parent


def cache_dir_of_a_fresh_process(env: dict[str, str]) -> Path:
    out = subprocess.run(
        [sys.executable, "-c", "import footnav.pipeline.navigation.eskf, numba; print(numba.config.CACHE_DIR)"],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return Path(out.stdout.strip())


def test_cache_folder_is_named_by_the_hash_of_all_pipeline_sources() -> None:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    assert cache_dir_of_a_fresh_process(env) == PIPELINE / "__pycache__" / f"numba-{sources_digest(PIPELINE)}"


def test_an_edited_kernel_in_a_subfolder_changes_the_key(tmp_path: Path) -> None:
    """A kernel module two folders down (``navigation/eskf.py``) edited by one comment: a new folder,
    so numba cannot load the machine code of the old source; a module added anywhere: a new folder too."""
    copy = tmp_path / "pipeline"
    shutil.copytree(PIPELINE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    before = sources_digest(copy)
    assert before == sources_digest(PIPELINE)
    kernel = copy / "navigation" / "eskf.py"
    kernel.write_text(kernel.read_text() + "\n# edited\n")
    edited = sources_digest(copy)
    assert edited != before
    (copy / "stance" / "new_module.py").write_text("")
    assert sources_digest(copy) not in (before, edited)


def test_a_cache_folder_given_by_the_environment_is_kept(tmp_path: Path) -> None:
    assert cache_dir_of_a_fresh_process(dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))) == tmp_path


_FIRST_RUN = """
import json, sys
from footnav.pipeline.navigation import warm
empty = warm.cache_is_empty()
from footnav.app import navigate, read_recording
navigate(read_recording(sys.argv[1]))
from footnav.pipeline.navigation._kernels import run_filter_kernel
from footnav.pipeline.stance import detectors, levels
kernels = (run_filter_kernel, detectors._statistic_kernel, detectors._adaptive_threshold_kernel, levels.height_update)
print(json.dumps({"empty": empty, "cores": warm._cores(), "kernels": {
    k.py_func.__name__: [sum(k.stats.cache_hits.values()), sum(k.stats.cache_misses.values()), len(k.overloads)]
    for k in kernels}}))
"""


def test_a_first_run_builds_the_filter_in_a_second_process_and_compiles_nothing_twice(tmp_path: Path) -> None:
    """With an empty cache, the navigator's first construction compiles the filter kernel in a child
    process (``footnav.pipeline.navigation.warm``) while it compiles the detector's: the navigation
    then loads the filter from the cache the child wrote (a hit, no miss) and reuses the detector
    kernels it built (one compiled overload each, so nothing was compiled twice for other types)."""
    walk = tmp_path / "walk.csv"
    from benchmarks.startup import write_walk_csv

    write_walk_csv(walk, 0.5)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run(
        [sys.executable, "-c", _FIRST_RUN, str(walk)], env=env, capture_output=True, text=True, check=True, timeout=600
    )
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["empty"] is True
    kernels = report["kernels"]
    for name in ("_statistic_kernel", "_adaptive_threshold_kernel", "height_update"):
        assert kernels[name] == [0, 1, 1], (name, kernels[name])  # compiled here once, by the build
    if report["cores"] >= 2:
        assert kernels["run_filter_kernel"] == [1, 0, 1]  # built by the child, loaded from the cache
    else:
        assert kernels["run_filter_kernel"] == [0, 1, 1]  # one core: compiled here, as before


_FIRST_EXPORT = """
import json, sys
from footnav.app.cli import main
from footnav.app.commands import export
from footnav.device.files.numeric_csv import _parse_rows
from footnav.device.files.table_csv import _render
from footnav.pipeline.navigation import warm
from footnav.pipeline.navigation._kernels import run_filter_kernel
built = []
def build_and_note(also=None):  # the real build, then what it left compiled
    warm.build_kernels(also)
    built.append([len(_render.overloads), len(_parse_rows.overloads)])
export.build_kernels = build_and_note
main(["export", sys.argv[1], "-o", sys.argv[2]])
print(json.dumps({"cores": warm._cores(), "built": built, "kernels": {
    k.py_func.__name__: [sum(k.stats.cache_hits.values()), sum(k.stats.cache_misses.values()), len(k.overloads)]
    for k in (_render, run_filter_kernel, _parse_rows)}}))
"""


def test_a_first_export_compiles_the_csv_kernels_beside_the_filter_and_once(tmp_path: Path) -> None:
    """``footnav export`` of a CSV to CSV with an empty cache: the writer's and the reader's kernels are compiled
    by the build while the child compiles the filter, with the types they are called with (one overload each, no
    second compile); the file was read by ``np.loadtxt``, and the next export reads it with the cached reader."""
    walk, track = tmp_path / "walk.csv", tmp_path / "track.csv"
    from benchmarks.startup import write_walk_csv

    write_walk_csv(walk, 0.5)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    reports = []
    for _ in range(2):
        out = subprocess.run(
            [sys.executable, "-c", _FIRST_EXPORT, str(walk), str(track)],
            env=env, capture_output=True, text=True, check=True, timeout=600,
        )  # fmt: skip
        reports.append(json.loads(out.stdout.strip().splitlines()[-1]))
        assert track.read_text().count("\n") == 1 + 6000  # header and every sample (30 s at 200 Hz)
    first, second = reports
    if first["cores"] >= 2:
        assert first["built"] == [[1, 1]]  # compiled by the build
        assert first["kernels"] == {"_render": [0, 1, 1], "run_filter_kernel": [1, 0, 1], "_parse_rows": [0, 1, 1]}
        assert second["kernels"]["_parse_rows"] == [1, 0, 1]  # the second export read with it, from the cache
    else:  # one core: no build; each kernel compiles when first called, the reader on the second run
        assert first["built"] == [[0, 0]]
        assert first["kernels"] == {"_render": [0, 1, 1], "run_filter_kernel": [0, 1, 1], "_parse_rows": [0, 0, 0]}
        assert second["kernels"]["_parse_rows"] == [0, 1, 1]
    assert second["kernels"]["run_filter_kernel"] == [1, 0, 1] and second["kernels"]["_render"] == [1, 0, 1]
