"""Shared fixtures: where the real recordings are (``../shared/data`` beside the checkout)."""

from __future__ import annotations

import shutil
import signal
from pathlib import Path

import pytest

if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    # A suite started as a background job of a shell without job control has Ctrl-C ignored, and its
    # children inherit that: the tests that stop a command with SIGINT would wait for it forever. A
    # handled signal is reset to its default in the children.
    signal.signal(signal.SIGINT, signal.default_int_handler)

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real recordings; tests that need them skip with the reason when the folder is absent."""
    if not (SHARED_DATA / "DATA.md").exists():
        pytest.skip(f"real recordings not found at {SHARED_DATA} (the shared/ folder beside the checkout)")
    return SHARED_DATA


FOLDER_TRIALS = ("2017-11-27-11-12-44.mat", "2017-12-15-18-01-18.mat", "2018-02-22-10-09-36.mat")
"""The PyShoe trials of :func:`recordings_folder`."""


@pytest.fixture(scope="module")
def recordings_folder(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder of real recordings: two PyShoe trials, a third in the subfolder ``vicon``, x-io's closed walk."""
    root = tmp_path_factory.mktemp("recordings")
    (root / "vicon").mkdir()
    for name in FOLDER_TRIALS[:2]:
        shutil.copy(shared_data / "pyshoe-vicon" / name, root / name)
    shutil.copy(shared_data / "pyshoe-vicon" / FOLDER_TRIALS[2], root / "vicon" / FOLDER_TRIALS[2])
    shutil.copy(shared_data / "xio-gait-tracking" / "short_walk.csv", root / "short_walk.csv")
    return root


@pytest.fixture(autouse=True)
def _isolated_calibration_dir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """No test sees the user's calibration files (``$FOOTNAV_CALIBRATION_DIR`` -> an empty folder)."""
    monkeypatch.setenv("FOOTNAV_CALIBRATION_DIR", str(tmp_path_factory.mktemp("calibration")))
