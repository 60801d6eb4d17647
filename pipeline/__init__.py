"""Estimation on streamed samples: detectors, the error-state Kalman filter, and the stage runner.

Estimators here are pure and synchronous (numpy, numba); only ``footnav.pipeline.runner`` knows asyncio.
Re-exported: the sample and estimate types, the errors, the stage runner and the trajectory metrics.
"""

import hashlib
import os
import shutil
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .errors import FootnavError as FootnavError
    from .errors import InputFormatError as InputFormatError
    from .metrics import AteResult as AteResult
    from .metrics import armse_2d_pyshoe as armse_2d_pyshoe
    from .metrics import ate as ate
    from .metrics import loop_closure_error as loop_closure_error
    from .metrics import path_length_m as path_length_m
    from .nav_types import ClearanceSeries as ClearanceSeries
    from .nav_types import NavBatch as NavBatch
    from .nav_types import SmoothedSpan as SmoothedSpan
    from .nav_types import concat_batches as concat_batches
    from .runner import AidedNavigator as AidedNavigator
    from .runner import BatchNavigator as BatchNavigator
    from .runner import NavSink as NavSink
    from .runner import SourceItem as SourceItem
    from .runner import run_pipeline as run_pipeline
    from .samples import ImuBatch as ImuBatch
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)


def sources_digest(root: Path) -> str:
    """The first 16 hex digits of a SHA-256 over every ``*.py`` below ``root``, subfolders included,
    each with its path relative to ``root``, in sorted order."""
    digest = hashlib.sha256()
    for source in sorted(root.rglob("*.py")):
        digest.update(source.relative_to(root).as_posix().encode() + b"\0" + source.read_bytes())
    return digest.hexdigest()[:16]


def _key_numba_cache_by_source() -> None:
    """Put numba's on-disk cache in a folder named by a hash of every source of this package.

    Numba keys each cached kernel by its own module's file only, so a kernel that inlines a function
    from another module (the smoother's pass inlines ``eskf._correct``) kept running the old code
    after that other module changed, until its own file changed too (found when ``eskf`` changed and
    the smoother's last sample no longer matched the filter's). With the folder keyed by every
    source, any change recompiles (about 10 s, once; the folders of older sources are removed).
    Left alone when ``NUMBA_CACHE_DIR`` is set or the folder cannot be written (numba then uses its
    own locations).
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return
    here = Path(__file__).resolve().parent
    cache = here / "__pycache__" / f"numba-{sources_digest(here)}"
    if not cache.is_dir():
        for old in cache.parent.glob("numba-*"):  # the kernels of sources that no longer exist
            shutil.rmtree(old, ignore_errors=True)
        try:
            cache.mkdir(parents=True, exist_ok=True)
        except OSError:
            return
    if not os.access(cache, os.W_OK):
        return
    # numba reads the variable when it is first imported (not here: importing this package for its
    # loaders or errors must not load numba); processes started from here inherit it
    os.environ["NUMBA_CACHE_DIR"] = str(cache)
    numba = sys.modules.get("numba")
    if numba is not None:  # imported before this package: set its configuration directly
        numba.config.CACHE_DIR = str(cache)


_key_numba_cache_by_source()
