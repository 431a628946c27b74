"""What every benchmark records next to its numbers: the machine, the versions, the command."""

from __future__ import annotations

import argparse
import json
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any

from taskforge.machine import machine

RESULTS = Path(__file__).resolve().parent / "results"


def versions(*packages: str) -> dict[str, str]:
    return {p: metadata.version(p) for p in packages}


def write_result(name: str, payload: dict[str, Any]) -> Path:
    """Write `benchmarks/results/<name>.json` with the command line, machine and time added."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    record = {
        "benchmark": name,
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": machine(),
        **payload,
    }
    path = RESULTS / f"{name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(record, indent=2) + "\n")
    tmp.replace(path)
    return path


def print_table(headers: list[str], rows: list[list[Any]]) -> None:
    cells = [[str(h) for h in headers]] + [[f"{c:,.1f}" if isinstance(c, float) else str(c) for c in r] for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    for k, row in enumerate(cells):
        print("  ".join(c.rjust(w) for c, w in zip(row, widths)))
        if k == 0:
            print("  ".join("-" * w for w in widths))


def advance_run(curriculum: Path, run_dir: Path, seed: int, total: int, chunk: int) -> int:
    """Train one benchmark run up to `chunk` more env steps (never past `total`), resuming from
    its checkpoint; returns its step count. Long comparisons span sessions this way. A finished
    run committed without its checkpoint (metrics only) is left as it is."""
    from taskforge.run import RunDir
    from taskforge.training import Interrupted, train

    run = RunDir(run_dir)
    done = run.steps_done()
    if done < total:
        # the run's length is `total` (the learning-rate schedule spans it); the chunk only pauses it
        try:
            train(curriculum, run_dir=run_dir, seed=seed, steps=total, stop_at=done + chunk, resume=True, progress=False)
        except Interrupted as exc:  # Ctrl-C/SIGTERM: the checkpoint is saved; say so in one line, as `taskforge train` does
            print(str(exc), file=sys.stderr)
            raise SystemExit(130) from None
        done = run.steps_done()
    return done


def chunked_parser(doc: str, chunk_steps: int) -> argparse.ArgumentParser:
    """The arguments every resumable comparison takes: which seeds, how far to advance each run
    in this call, and a report of what exists without training."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--chunk-steps", type=int, default=chunk_steps, help="advance each run by at most this many env steps per call")
    parser.add_argument("--report-only", action="store_true", help="summarise the runs so far, train nothing")
    return parser


def pyplot():
    """matplotlib's pyplot on the Agg backend (files only, no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, out: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
