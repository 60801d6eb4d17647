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
    import numba.np.linalg

    width_checks = []  # numba's LAPACK integer-width check, counted
    check_width = numba.np.linalg._check_lapack_int_width
    numba.np.linalg._check_lapack_int_width = lambda: (width_checks.append(1), check_width())[1]
    from footnav.pipeline.jit import njit

    @njit
    def twice(x):  # numba's first compile loads all its implementations
        return 2.0 * x

    assert twice(np.ones(3)).sum() == 6.0
    print("scipy.linalg loaded:", "scipy.linalg" in sys.modules or "scipy.linalg.cython_blas" in sys.modules)
    print("width check ran:", len(width_checks) > 0)

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


def _python(code: str, *args: str, **env_vars: str) -> list[str]:
    """The lines ``code`` prints in a fresh interpreter, with ``env_vars`` as the only ``FOOTNAV_NUMBA_CFFI``."""
    env = {k: v for k, v in os.environ.items() if k != "FOOTNAV_NUMBA_CFFI"} | env_vars
    proc = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=300, check=False, env=env
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.splitlines()


def test_numba_loads_without_scipy_linalg_and_blas_still_works() -> None:
    lines = _python(PROBE)
    assert lines[:4] == [
        "scipy.linalg loaded: False",
        "width check ran: True",
        "BLAS product right: True",
        "real BLAS module: True",
    ]


@pytest.mark.skipif(importlib.util.find_spec("cffi") is None, reason="cffi not installed: numba has no cffi support")
def test_cffi_support_is_left_out_only_when_asked() -> None:
    assert _python(PROBE)[-1] == "numba cffi support: True"  # the Python API leaves numba as it is
    lines = _python(PROBE, FOOTNAV_NUMBA_CFFI="0")  # what the footnav command sets
    assert lines[-1] == "numba cffi support: False"
    check = "import footnav.pipeline.jit, cffi; print(cffi.FFI().sizeof('int'))"
    assert _python(check, FOOTNAV_NUMBA_CFFI="0") == ["4"]  # cffi itself still imports and works


RACE = textwrap.dedent(
    """
    import sys, threading, time
    delay_s = float(sys.argv[1])
    result = {}

    def footnav():
        import footnav.pipeline.jit
        result["footnav"] = "ok"

    def scipy():  # another thread importing SciPy while footnav's first import loads numba
        time.sleep(delay_s)
        try:
            import scipy.optimize
            result["scipy"] = "ok"
        except Exception as exc:
            result["scipy"] = repr(exc)

    threads = [threading.Thread(target=footnav), threading.Thread(target=scipy)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    print(result["footnav"], result["scipy"])
    """
)


@pytest.mark.parametrize("delay_s", [0.0, 0.02, 0.05, 0.1])
def test_other_threads_import_scipy_meanwhile(delay_s: float) -> None:
    assert _python(RACE, str(delay_s), FOOTNAV_NUMBA_CFFI="0") == ["ok ok"]


def test_cffi_is_hidden_from_the_loading_thread_only() -> None:
    import threading

    from footnav.pipeline.jit import _HiddenFromThisThread

    sys.modules.pop("hidden_probe_module", None)
    hidden = _HiddenFromThisThread("hidden_probe_module")
    sys.meta_path.insert(0, hidden)
    try:
        with pytest.raises(ImportError, match="left out while numba loads"):
            __import__("hidden_probe_module")
        seen: list[str] = []

        def other_thread() -> None:  # reaches the usual finders: the module does not exist
            try:
                __import__("hidden_probe_module")
            except ModuleNotFoundError as exc:
                seen.append(type(exc).__name__)

        thread = threading.Thread(target=other_thread)
        thread.start()
        thread.join()
        assert seen == ["ModuleNotFoundError"]
    finally:
        sys.meta_path.remove(hidden)
