"""Where training numbers go: a JSONL file (one record per update, easy to read back for plots
and resumes) and TensorBoard events (for watching live)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from torch.utils.tensorboard import SummaryWriter

from taskforge.atomic import atomic_write


class JsonlLog:
    """Append-only JSON lines, flushed per record so a kill loses at most the line being written."""

    def __init__(self, path: Path):
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file = path.open("a", encoding="utf-8")

    def write(self, record: dict[str, Any]) -> None:
        self._file.write(json.dumps(record) + "\n")
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """Records of a JSONL file; a torn last line (killed mid-write) is skipped."""
    if not path.exists():
        return []
    records = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


def truncate_after(path: Path, step: int) -> None:
    """On resume, drop records written after the checkpoint (they will be written again)."""
    kept = [r for r in read_jsonl(path) if r.get("step", 0) <= step]
    text = "".join(json.dumps(r) + "\n" for r in kept)
    atomic_write(path, lambda f: f.write(text.encode()))


class MetricsLogger:
    def __init__(self, run_dir: Path, resume_step: int | None):
        if resume_step is not None:
            for name in ("metrics.jsonl", "events.jsonl"):
                truncate_after(run_dir / name, resume_step)
        self.metrics = JsonlLog(run_dir / "metrics.jsonl")
        self.events = JsonlLog(run_dir / "events.jsonl")
        self.tensorboard = SummaryWriter(str(run_dir / "tensorboard"), purge_step=resume_step)

    def log(self, step: int, record: dict[str, Any]) -> None:
        self.metrics.write({"step": step, **record})
        for key, value in record.items():
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                self.tensorboard.add_scalar(key, value, step)

    def event(self, record: dict[str, Any]) -> None:
        self.events.write(record)
        self.tensorboard.add_text("curriculum", json.dumps(record), record["step"])

    def close(self) -> None:
        self.metrics.close()
        self.events.close()
        self.tensorboard.close()
