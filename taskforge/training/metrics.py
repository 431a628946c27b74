"""Where training numbers go: a JSONL file (one record per update, easy to read back for plots
and resumes) and TensorBoard events (for watching live)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from torch.utils.tensorboard import SummaryWriter

from taskforge.atomic import atomic_write
from taskforge.run import RunDir, read_jsonl


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


def truncate_after(path: Path, step: int) -> None:
    """On resume, drop records written after the checkpoint (they will be written again)."""
    kept = [r for r in read_jsonl(path) if r.get("step", 0) <= step]
    text = "".join(json.dumps(r) + "\n" for r in kept)
    atomic_write(path, lambda f: f.write(text.encode()))


class MetricsLogger:
    """`resume_step`: drop what a resumed run logged after its checkpoint. `fresh`: drop what a run
    killed before its first checkpoint logged (it starts again from step 0)."""

    def __init__(self, run: RunDir, resume_step: int | None, fresh: bool = False):
        if resume_step is not None or fresh:
            for path in (run.metrics, run.events):
                truncate_after(path, -1 if fresh else resume_step)
        self.metrics = JsonlLog(run.metrics)
        self.events = JsonlLog(run.events)
        self.tensorboard = SummaryWriter(str(run.tensorboard), purge_step=resume_step)

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
