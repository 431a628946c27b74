"""Shared fixtures. Tests run the real simulators; they are sized to take seconds each."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
TASKS = ROOT / "tasks"
PICK_PLACE = TASKS / "metaworld" / "pick_place.yaml"



@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture()
def one_torch_thread():
    """Agent tests run with one torch thread: deterministic and fair to the other core."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
