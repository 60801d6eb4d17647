"""``scipy.io.loadmat`` in a child process, so that a corrupt file cannot crash footnav.

scipy's C reader can crash its process on a corrupt file (a segmentation fault, found by fuzzing);
that must be an error message. One child (``python -m footnav.device.files.mat_reader``) is started on first
use and kept: it reads a path per line on stdin and answers with a length-prefixed pickle of the
variables, or of the exception it raised. A crash costs only that file: the next load starts a new
child. A plain subprocess rather than ``multiprocessing``: a spawn or fork-server child re-imports the
caller's main script, which re-runs a script without a ``__main__`` guard (and made its load fail).
"""

from __future__ import annotations

import atexit
import os
import pickle
import struct
import subprocess
import sys
import threading
from pathlib import Path
from typing import IO, Any

_HEADER = struct.Struct("<Q")
_ROOT = Path(__file__).resolve().parents[1]


class ReaderCrashedError(Exception):
    """The child process died reading a file."""


def _loadmat(path: str) -> dict[str, object]:
    from scipy.io import loadmat

    return {k: v for k, v in loadmat(path).items() if not k.startswith("__")}


class _Child:
    """The kept child process; one load at a time."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._proc: subprocess.Popen[bytes] | None = None
        atexit.register(self.close)

    def _start(self) -> subprocess.Popen[bytes]:
        if self._proc is not None and self._proc.poll() is not None:
            self.close()  # died since the last load
        if self._proc is None:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "footnav.device.files.mat_reader"],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                cwd=_ROOT,  # the package is importable there even when footnav is not installed
            )
        return self._proc

    def load(self, path: Path) -> dict[str, object]:
        with self._lock:
            proc = self._start()
            assert proc.stdin is not None and proc.stdout is not None
            try:
                proc.stdin.write(str(path.resolve()).encode() + b"\n")
                proc.stdin.flush()
                (size,) = _HEADER.unpack(_read_exactly(proc.stdout, _HEADER.size))
                ok, value = pickle.loads(_read_exactly(proc.stdout, size))
            except (OSError, EOFError, struct.error):
                proc.kill()
                self.close()
                raise ReaderCrashedError(f"the MATLAB reader crashed (exit code {proc.returncode})") from None
        if not ok:
            raise value
        return value

    def close(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        for pipe in (proc.stdin, proc.stdout):  # EOF on stdin ends the child
            if pipe is not None:
                pipe.close()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _read_exactly(stream: IO[bytes], n: int) -> bytes:
    data = stream.read(n)
    if data is None or len(data) != n:
        raise EOFError
    return data


_child = _Child()


def load_mat(path: Path) -> dict[str, object]:
    """The variables of the .mat file at ``path`` (names starting ``__`` dropped).

    Raises
    ------
    ReaderCrashedError
        the reader's process died on this file.
    Exception
        whatever ``scipy.io.loadmat`` raised on it.
    """
    return _child.load(path)


def _serve(stdin: IO[bytes], stdout: IO[bytes]) -> None:
    for line in stdin:
        result: tuple[bool, Any]
        try:
            result = (True, _loadmat(line.decode().rstrip("\n")))
        except Exception as exc:  # sent back to the caller, which raises it
            result = (False, exc)
        try:
            blob = pickle.dumps(result)
        except Exception as exc:
            blob = pickle.dumps((False, TypeError(f"unpicklable result: {exc}")))
        stdout.write(_HEADER.pack(len(blob)) + blob)
        stdout.flush()


if __name__ == "__main__":
    _serve(sys.stdin.buffer, sys.stdout.buffer)
    os._exit(0)  # every answer is flushed; the caller's exit waits for this one, not for the interpreter's teardown
