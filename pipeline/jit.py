"""Numba's ``njit`` for footnav's kernels, imported without two of numba's start-up probes.

When numba first compiles or loads a kernel from its cache, it imports all its implementations, and
two of them probe for optional libraries that footnav's kernels never use:

- ``numba.np.arraymath`` checks that BLAS is there by importing ``scipy.linalg.cython_blas``, which
  imports all of ``scipy.linalg`` and, through SciPy's array-API layer, ``numpy.f2py``. footnav's
  kernels call no BLAS (their solves are written out, e.g. ``footnav.pipeline.smoothing.rts``). It is
  imported here with a placeholder module under that name, removed right after: numba's check of the
  LAPACK integer width still runs (it reads ``scipy.__config__``), and code that does call BLAS imports
  the real module when numba compiles the call and again when it first runs.
- ``numba.core.typing.cffi_utils`` builds a ``cffi.FFI`` when cffi is installed (it comes with
  cryptography and Jupyter), which builds pycparser's tables. Only when ``FOOTNAV_NUMBA_CFFI=0`` (the
  ``footnav`` command sets it: its processes run footnav's kernels only), it is imported with cffi
  hidden, so numba types no cffi functions in that process; cffi itself stays importable.

Why and what each saves: docs/design/architecture.md, "A command's start and end".
"""

from __future__ import annotations

import os
import sys
import types


def _import_with_stand_in(module: str, probed: str, stand_in: types.ModuleType | None) -> None:
    """Import ``module`` while ``sys.modules[probed]`` is ``stand_in`` (``None``: the import fails), then
    remove it; nothing is done when either is already imported."""
    if probed in sys.modules or module in sys.modules:
        return
    sys.modules[probed] = stand_in  # type: ignore[assignment]
    try:
        __import__(module)
    except Exception:  # another numba: its own import at first use then tells
        pass
    finally:
        del sys.modules[probed]


_import_with_stand_in("numba.np.arraymath", "scipy.linalg.cython_blas", types.ModuleType("scipy.linalg.cython_blas"))
if os.environ.get("FOOTNAV_NUMBA_CFFI") == "0":
    _import_with_stand_in("numba.core.typing.cffi_utils", "cffi", None)

from numba import njit  # noqa: E402

__all__ = ["njit"]
