"""The compiled kernels' on-disk cache is keyed by every source below ``pipeline/``, subfolders
included (``footnav.pipeline.sources_digest``)."""

from __future__ import annotations

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
