"""What a benchmark's figures were measured on: CPU, cores, load, OS, Python and the numerics' versions."""

from __future__ import annotations

import os
import platform
from pathlib import Path

import numba
import numpy as np


def machine() -> list[tuple[str, str]]:
    """What the figures were measured on."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = os.cpu_count() or 0
    affinity = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else cores
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return [
        ("CPU", cpu),
        ("cores", f"{cores} logical ({affinity} usable by this process); estimators use one"),
        ("load average (1 min)", f"{load:.2f} at start"),
        ("OS", platform.platform()),
        ("Python", platform.python_version()),
        ("numpy / numba", f"{np.__version__} / {numba.__version__}"),
    ]
