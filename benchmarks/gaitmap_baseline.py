"""gaitmap's ESKF + RTS smoother (``gaitmap.trajectory_reconstruction.RtsKalman``, defaults) timed on the
same samples, as a peer-tool baseline for ``python -m benchmarks --gaitmap PYTHON``.

gaitmap is not a dependency of footnav (it pins its own numpy, pandas and numba); it runs in the Python
given, in a child process, for example a virtual environment made with ``python3 -m venv gm &&
gm/bin/pip install gaitmap``. The child warms up (gaitmap compiles its own numba kernels), then times
``RtsKalman().estimate`` on the samples (specific force in m/s², rates converted to °/s as gaitmap takes
them) and prints the best wall time of ``repeats`` runs. RtsKalman is a forward filter and a backward
smoother over the whole recording, more work than footnav's causal filter alone, and what gaitmap offers
for the same task (a foot track from one IMU).
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

_CHILD = """
import sys, time
import numpy as np, pandas as pd
from gaitmap.trajectory_reconstruction import RtsKalman

data = np.load(sys.argv[1])
rate, repeats = float(sys.argv[2]), int(sys.argv[3])
frame = pd.DataFrame(
    np.column_stack([data[:, :3], np.rad2deg(data[:, 3:])]),
    columns=["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"],
)
RtsKalman().estimate(frame.iloc[:2000], sampling_rate_hz=rate)  # compile gaitmap's kernels
best = float("inf")
for _ in range(repeats):
    t0 = time.perf_counter()
    RtsKalman().estimate(frame, sampling_rate_hz=rate)
    best = min(best, time.perf_counter() - t0)
print(best)
"""


def gaitmap_wall_s(python: str, acc_b_mps2: NDArray[np.float64], gyr_b_radps: NDArray[np.float64], rate_hz: float,
                   repeats: int) -> float:  # fmt: skip
    """Best wall time, s, of gaitmap's ``RtsKalman().estimate`` on the (n, 3) samples, run by ``python``.

    Raises
    ------
    subprocess.CalledProcessError
        the child failed (gaitmap missing from that Python, for one).
    """
    with tempfile.TemporaryDirectory() as work:
        path = Path(work) / "samples.npy"
        np.save(path, np.column_stack([acc_b_mps2, gyr_b_radps]))
        out = subprocess.run(
            [python, "-c", _CHILD, str(path), str(rate_hz), str(repeats)], capture_output=True, text=True, check=True
        )
    return float(out.stdout.split()[-1])
