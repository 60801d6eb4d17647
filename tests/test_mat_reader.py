"""The .mat reader's child process (device/files/mat_reader.py): crashes are contained, scripts are safe."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from footnav.device.files import mat_reader
from scipy.io import savemat

ROOT = Path(__file__).resolve().parents[1]


def _trial(path: Path, n: int = 400) -> Path:
    """A small PyShoe-shaped trial: 200 Hz, standing still."""
    imu = np.zeros((n, 6))
    imu[:, 2] = -9.81
    savemat(path, {"ts": np.arange(n)[None, :] / 200.0, "imu": imu, "gt": np.zeros((n, 3))})
    return path


def test_a_script_without_a_main_guard_loads_a_mat_file(tmp_path: Path) -> None:
    script = tmp_path / "script.py"  # no `if __name__ == "__main__"`: a child must not re-run it
    script.write_text(
        "import sys\nfrom pathlib import Path\nfrom footnav.device.files.recordings import load_recording\n"
        "print(load_recording(Path(sys.argv[1])).t_s.size)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, str(script), str(_trial(tmp_path / "t.mat"))],
        check=False, capture_output=True, text=True, timeout=60, env=env,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "400"


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs a named pipe to hold the reader")
def test_a_reader_that_dies_is_an_error_and_the_next_load_works(tmp_path: Path) -> None:
    fifo = tmp_path / "never-written.mat"
    os.mkfifo(fifo)  # the reader blocks opening it until killed, as if it had crashed on the file
    mat_reader.load_mat(_trial(tmp_path / "ok.mat"))  # the child is running
    child = mat_reader._child._proc
    assert child is not None
    killer = threading.Timer(0.5, child.kill)
    killer.start()
    with pytest.raises(mat_reader.ReaderCrashedError, match="crashed"):
        mat_reader.load_mat(fifo)
    killer.join()
    assert mat_reader.load_mat(_trial(tmp_path / "again.mat"))["imu"].shape == (400, 6)


def test_scipy_errors_come_back_as_they_were_raised(tmp_path: Path) -> None:
    path = tmp_path / "text.mat"
    path.write_text("not a mat file at all\n")
    with pytest.raises(Exception) as raised:  # scipy's own kind (IndexError, ValueError...)
        mat_reader.load_mat(path)
    assert not isinstance(raised.value, mat_reader.ReaderCrashedError)


def test_the_reader_answers_every_path_and_ends_at_the_end_of_its_input(tmp_path: Path) -> None:
    paths = [_trial(tmp_path / f"{i}.mat", n) for i, n in enumerate((400, 300))]
    proc = subprocess.run(
        [sys.executable, "-m", "footnav.device.files.mat_reader"],
        input=b"".join(str(p).encode() + b"\n" for p in paths), capture_output=True, timeout=60, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    answers, rest = [], proc.stdout
    while rest:
        (size,) = mat_reader._HEADER.unpack(rest[: mat_reader._HEADER.size])
        answers.append(pickle.loads(rest[mat_reader._HEADER.size : mat_reader._HEADER.size + size]))
        rest = rest[mat_reader._HEADER.size + size :]
    assert [(ok, value["imu"].shape) for ok, value in answers] == [(True, (400, 6)), (True, (300, 6))]
