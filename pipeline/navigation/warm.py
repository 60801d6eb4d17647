"""The navigator's compiled kernels built on two cores when numba's cache has none of them yet.

A navigator needs two groups of kernels that do not call each other: the zero-velocity detector's
(``footnav.pipeline.stance.detectors``: the statistic, the adaptive threshold, the pairwise sums) with
the stance height update (``footnav.pipeline.stance.levels.height_update``), and the filter's
(``footnav.pipeline.navigation._kernels.run_filter_kernel`` with its update ``_update3_sym``). Numba
compiles in one thread under a process-wide lock, so the first navigator of a fresh install compiled
both groups one after the other. :func:`build_kernels` compiles the filter's group in a child process
while this one compiles the detector's; both write numba's on-disk cache (the folder
``footnav.pipeline`` keys by its sources), which this process then loads the filter from. Each group
is compiled by calling it on a few synthetic samples with the argument types a navigator passes, so
the navigator's own calls find them in the cache. A command adds its other kernels to this process's
share (``also``: ``footnav export``'s CSV writer). Why and what it saves:
docs/design/estimator.md, "Compiled filter kernels".
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

_BUILT: list[bool] = []
"""Holds True once :func:`build_kernels` has run in this process."""


def cache_is_empty() -> bool:
    """True when numba's cache folder (``NUMBA_CACHE_DIR``, which ``footnav.pipeline`` sets) holds no
    index of the filter kernel: a first run, or the sources changed. False when no folder is set."""
    folder = os.environ.get("NUMBA_CACHE_DIR")
    if not folder:
        return False
    return not any(Path(folder).rglob("_kernels.run_filter_kernel-*.nbi"))


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _still_samples(n: int = 256) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` samples of a level unit at rest at 100 Hz: time (n,), specific force and rate (n, 3)."""
    t_s = np.arange(n) / 100.0
    acc = np.zeros((n, 3))
    acc[:, 2] = 9.81
    return t_s, acc, np.zeros((n, 3))


def build_detector_kernels() -> None:
    """Compile the detector's kernels and the stance height update (by running them once)."""
    from footnav.pipeline.navigation import eskf
    from footnav.pipeline.navigation.navigator import NavConfig
    from footnav.pipeline.stance.detectors import StreamingDetector
    from footnav.pipeline.stance.levels import height_update

    _, acc, gyr = _still_samples()
    StreamingDetector(NavConfig().detector, 100.0).update(acc, gyr)
    n = eskf.N_STATE
    height_update(np.zeros(n + 1), np.eye(n), -1, 0.0, 1e-4, np.zeros((2, n)))


def build_filter_kernels() -> None:
    """Compile the filter kernel (by running it once on samples of a unit at rest)."""
    from footnav.pipeline.navigation import eskf
    from footnav.pipeline.navigation.alignment import align_from_still
    from footnav.pipeline.navigation.batches import NO_CLIPPED_RATES
    from footnav.pipeline.navigation.navigator import NavConfig, filter_start

    t_s, acc, gyr = _still_samples()
    x, P, par = filter_start(NavConfig(), 100.0, align_from_still(acc, gyr))
    n = t_s.shape[0]
    eskf.run_filter(
        x, P, acc, gyr, NO_CLIPPED_RATES, np.full(n, 0.01), np.zeros(n, np.bool_), np.zeros(n), par,
        np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 4)), np.empty((n, 4, 4)),
        np.zeros(eskf.N_CNT, np.int64), eskf.new_filter_state(),
    )  # fmt: skip


def build_kernels(also: Callable[[], object] | None = None) -> None:
    """Once per process: when the cache is empty and two cores are free to use, compile the filter's
    kernels in a child process while this one compiles the detector's, and then what ``also`` compiles
    (a command's other kernels, e.g. ``footnav export``'s CSV writer), then wait for the child.
    Otherwise nothing: each kernel is compiled (or loaded) when first called, as always."""
    if _BUILT:
        return
    _BUILT.append(True)
    if not cache_is_empty() or _cores() < 2:
        return
    # the child ends without the interpreter's teardown, which this process would wait for (0.2-0.3 s)
    code = "import os, footnav.pipeline.navigation.warm as w; w.build_filter_kernels(); os._exit(0)"
    child = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    try:
        build_detector_kernels()
        if also is not None:
            also()
    finally:
        child.wait()
