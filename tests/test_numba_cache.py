"""The compiled kernels' on-disk cache is keyed by every source of ``pipeline`` (``pipeline/__init__.py``)."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pipeline


def test_cache_folder_is_named_by_the_hash_of_all_pipeline_sources() -> None:
    """A kernel that inlines another module's function must be recompiled when that module changes;
    numba alone keys a kernel by its own file, so the folder name must change with any source."""
    here = Path(pipeline.__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(here.glob("*.py")):
        digest.update(source.name.encode() + source.read_bytes())
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    out = subprocess.run(
        [sys.executable, "-c", "import pipeline.eskf, numba; print(numba.config.CACHE_DIR)"],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert Path(out.stdout.strip()) == here / "__pycache__" / f"numba-{digest.hexdigest()[:16]}"


def test_a_cache_folder_given_by_the_environment_is_kept(tmp_path: Path) -> None:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run(
        [sys.executable, "-c", "import pipeline.eskf, numba; print(numba.config.CACHE_DIR)"],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert Path(out.stdout.strip()) == tmp_path
