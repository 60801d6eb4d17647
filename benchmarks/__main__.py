"""``python -m benchmarks``: see ``benchmarks.run``."""

from __future__ import annotations

import os

# one core: keep BLAS and numba from starting worker threads (set before numpy is imported)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

from benchmarks.run import main  # noqa: E402

raise SystemExit(main())
