"""Shared fixtures. Tests run the real simulators; they are sized to take seconds each."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TASKS = ROOT / "tasks"
PICK_PLACE = TASKS / "metaworld" / "pick_place.yaml"

# Gymnasium's checker warns that an unbounded Box is "probably too low/high"; ours is unbounded
# on purpose (observation noise may leave any finite box).
warnings.filterwarnings("ignore", message=".*Box observation space (minimum|maximum) value is.*")


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT
