"""Checkpoints that are never corrupt: write to a temporary file in the same folder, fsync, then
`os.replace` (atomic on POSIX). A kill at any moment leaves either the old file or the new one."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import torch


def atomic_write_bytes(path: Path, write: "callable") -> None:
    """Call `write(file_object)` into a temp file beside `path`, then atomically move it there."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save_checkpoint(state: dict[str, Any], path: Path) -> None:
    atomic_write_bytes(path, lambda f: torch.save(state, f))


def load_checkpoint(path: Path) -> dict[str, Any]:
    # Our own files hold numpy arrays and plain containers, which `weights_only` refuses.
    return torch.load(path, map_location="cpu", weights_only=False)


def save_json(data: Any, path: Path) -> None:
    atomic_write_bytes(path, lambda f: f.write((json.dumps(data, indent=2, default=str) + "\n").encode()))
