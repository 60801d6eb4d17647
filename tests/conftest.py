"""Shared fixtures: where the real recordings are (``../shared/data`` beside the checkout)."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real recordings; tests that need them skip with the reason when the folder is absent."""
    if not (SHARED_DATA / "DATA.md").exists():
        pytest.skip(f"real recordings not found at {SHARED_DATA} (the shared/ folder beside the checkout)")
    return SHARED_DATA


@pytest.fixture(autouse=True)
def _isolated_calibration_dir(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """No test sees the user's calibration files (``$FOOTNAV_CALIBRATION_DIR`` -> an empty folder)."""
    monkeypatch.setenv("FOOTNAV_CALIBRATION_DIR", str(tmp_path_factory.mktemp("calibration")))
