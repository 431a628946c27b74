"""Shared fixtures. Tests run the real simulators; they are sized to take seconds each."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TASKS = ROOT / "tasks"
PICK_PLACE = TASKS / "metaworld" / "pick_place.yaml"



@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT
