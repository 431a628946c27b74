"""Checkpoints and run files that are never corrupt (see `taskforge.atomic`): a kill at any
moment leaves either the old file or the new one."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch

from taskforge.atomic import atomic_write


def save_checkpoint(state: dict[str, Any], path: Path) -> None:
    atomic_write(path, lambda f: torch.save(state, f))


def load_checkpoint(path: Path) -> dict[str, Any]:
    # Our own files hold numpy arrays and plain containers, which `weights_only` refuses.
    return torch.load(path, map_location="cpu", weights_only=False)


def save_json(data: Any, path: Path) -> None:
    atomic_write(path, lambda f: f.write((json.dumps(data, indent=2, default=str) + "\n").encode()))
