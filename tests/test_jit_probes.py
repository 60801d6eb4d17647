"""``footnav.pipeline.jit``: numba loads without importing ``scipy.linalg`` (and, when the ``footnav`` command
asks, without its cffi support), and nothing numba or the user needs is lost: BLAS calls compile and run,
the LAPACK width check still runs, cffi stays importable. Each case in a fresh interpreter, where numba is
not yet imported."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap

import pytest

PROBE = textwrap.dedent(
    """
    import sys
    import numpy as np
    from footnav.pipeline.jit import njit

    @njit
    def twice(x):  # numba's first compile loads all its implementations
        return 2.0 * x

    assert twice(np.ones(3)).sum() == 6.0
    print("scipy.linalg loaded:", "scipy.linalg" in sys.modules or "scipy.linalg.cython_blas" in sys.modules)
    print("width check ran:", "scipy.__config__" in sys.modules)

    @njit
    def product(a, b):  # BLAS (dgemm) through numba
        return a @ b

    a = np.arange(12.0).reshape(3, 4)
    b = np.arange(8.0).reshape(4, 2)
    print("BLAS product right:", bool(np.array_equal(product(a, b), a @ b)))
    print("real BLAS module:", hasattr(sys.modules["scipy.linalg.cython_blas"], "__pyx_capi__"))
    from numba.core.typing import cffi_utils
    print("numba cffi support:", cffi_utils.SUPPORTED)
    """
)


def _probe(**env_vars: str) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k != "FOOTNAV_NUMBA_CFFI"} | env_vars
    proc = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=300, check=False, env=env
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.splitlines()


def test_numba_loads_without_scipy_linalg_and_blas_still_works() -> None:
    lines = _probe()
    assert lines[:4] == [
        "scipy.linalg loaded: False",
        "width check ran: True",
        "BLAS product right: True",
        "real BLAS module: True",
    ]


@pytest.mark.skipif(importlib.util.find_spec("cffi") is None, reason="cffi not installed: numba has no cffi support")
def test_cffi_support_is_left_out_only_when_asked() -> None:
    assert _probe()[-1] == "numba cffi support: True"  # the Python API leaves numba as it is
    lines = _probe(FOOTNAV_NUMBA_CFFI="0")  # what the footnav command sets
    assert lines[-1] == "numba cffi support: False"
    check = ["-c", "import footnav.pipeline.jit, cffi; print(cffi.FFI().sizeof('int'))"]
    env = os.environ | {"FOOTNAV_NUMBA_CFFI": "0"}
    out = subprocess.run([sys.executable, *check], capture_output=True, text=True, timeout=300, env=env, check=True)
    assert out.stdout.strip() == "4"  # cffi itself still imports and works
