"""Numba's ``njit`` for footnav's kernels, imported without two of numba's start-up probes.

When numba first compiles or loads a kernel from its cache, it imports all its implementations, and
two of them probe for optional libraries that footnav's kernels never use:

- ``numba.np.arraymath`` checks that BLAS is there by importing ``scipy.linalg.cython_blas``, which
  imports all of ``scipy.linalg`` and, through SciPy's array-API layer, ``numpy.f2py``. footnav's
  kernels call no BLAS (their solves are written out, e.g. ``footnav.pipeline.smoothing.rts``). Here it
  is imported while numba's ``ensure_blas`` is, for that one import, a check that SciPy's compiled BLAS
  module is installed (its file) followed by numba's own LAPACK integer-width check. Code that does
  call BLAS later runs numba's ``ensure_blas`` as before, and imports the real module when it first runs.
- ``numba.core.typing.cffi_utils`` builds a ``cffi.FFI`` when cffi is installed (it comes with
  cryptography and Jupyter), which builds pycparser's tables. Only when ``FOOTNAV_NUMBA_CFFI=0`` (the
  ``footnav`` command sets it: its processes run footnav's kernels only), it is imported while cffi
  cannot be imported from this thread, so numba types no cffi functions in that process; other
  threads, and this one afterwards, import cffi as usual.

Nothing is put in ``sys.modules`` that another thread could see. Why and what each saves:
docs/design/architecture.md, "A command's start and end".
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import os
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType


def _scipy_blas_installed() -> None:
    """Numba's ``ensure_blas`` without importing SciPy's BLAS module: raise ``ImportError`` as it does when
    ``scipy/linalg/cython_blas`` is not installed, then check the LAPACK integer width as it does (numba
    0.68 and later)."""
    import numba.np.linalg

    spec = importlib.util.find_spec("scipy")
    folders = spec.submodule_search_locations if spec is not None else None
    suffixes = importlib.machinery.EXTENSION_SUFFIXES
    if not any(Path(f, "linalg", "cython_blas" + s).is_file() for f in folders or () for s in suffixes):
        raise ImportError("scipy 0.16+ is required for linear algebra")
    width_check = getattr(numba.np.linalg, "_check_lapack_int_width", None)  # numba 0.68 and later
    if width_check is not None:
        width_check()


def _import_array_implementations() -> None:
    """Import ``numba.np.arraymath`` with :func:`_scipy_blas_installed` as its BLAS check."""
    if "numba.np.arraymath" in sys.modules or "scipy.linalg" in sys.modules:
        return  # loaded already, or numba's check costs nothing
    import numba.np.linalg

    ensure_blas = numba.np.linalg.ensure_blas
    numba.np.linalg.ensure_blas = _scipy_blas_installed
    try:
        import numba.np.arraymath  # its BLAS check runs at import: `from numba.np.linalg import ensure_blas`
    finally:
        numba.np.linalg.ensure_blas = ensure_blas
        arraymath = sys.modules.get("numba.np.arraymath")
        if arraymath is not None:
            arraymath.ensure_blas = ensure_blas  # type: ignore[attr-defined]


class _HiddenFromThisThread(importlib.abc.MetaPathFinder):
    """An import finder under which ``name`` cannot be imported from the thread that made it."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.thread = threading.get_ident()

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname == self.name and threading.get_ident() == self.thread:
            raise ImportError(f"{fullname} is left out while numba loads", name=fullname)
        return None


def _import_cffi_typing_without_cffi() -> None:
    """Import ``numba.core.typing.cffi_utils`` while cffi cannot be imported from this thread."""
    if "cffi" in sys.modules or "numba.core.typing.cffi_utils" in sys.modules:
        return
    hidden = _HiddenFromThisThread("cffi")
    sys.meta_path.insert(0, hidden)
    try:
        import numba.core.typing.cffi_utils  # noqa: F401
    finally:
        sys.meta_path.remove(hidden)


_import_array_implementations()
if os.environ.get("FOOTNAV_NUMBA_CFFI") == "0":
    _import_cffi_typing_without_cffi()

from numba import njit  # noqa: E402

__all__ = ["njit"]
