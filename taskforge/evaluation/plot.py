"""`taskforge plot`: learning curves (return, success) from a run's metrics.jsonl, with the
curriculum's promotions marked as vertical lines."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display on training machines
import matplotlib.pyplot as plt  # noqa: E402

from taskforge.spec import SpecError  # noqa: E402
from taskforge.training.metrics import read_jsonl  # noqa: E402


def plot_run(run_dir: str | Path, out: str | Path | None = None) -> Path:
    run_dir = Path(run_dir)
    metrics = read_jsonl(run_dir / "metrics.jsonl")
    if not metrics:
        raise SpecError.single(run_dir, "", "no metrics.jsonl with records; expected a taskforge run directory")
    events = read_jsonl(run_dir / "events.jsonl")
    out = Path(out) if out else run_dir / "curves.png"

    fig, (ax_ret, ax_succ) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    rows = [m for m in metrics if m.get("return_mean") is not None]
    ax_ret.plot([m["step"] for m in rows], [m["return_mean"] for m in rows], lw=1)
    ax_ret.set_ylabel("episode return (train)")
    rows = [m for m in metrics if m.get("success_rate") is not None]
    ax_succ.plot([m["step"] for m in rows], [m["success_rate"] for m in rows], lw=1, label="train episodes")
    evals = [m for m in metrics if "eval_success_rate" in m]
    if evals:
        ax_succ.plot([m["step"] for m in evals], [m["eval_success_rate"] for m in evals], "o-", label="held-out eval")
    ax_succ.set_ylabel("success rate")
    ax_succ.set_ylim(-0.02, 1.02)
    ax_succ.set_xlabel("environment steps")
    for ax in (ax_ret, ax_succ):
        for e in events:
            ax.axvline(e["step"], color="grey", ls="--", lw=0.8)
    for e in events:
        ax_ret.annotate(f"{e['kind']} → {e['to_stage']}", (e["step"], 1.0), xycoords=("data", "axes fraction"),
                        rotation=90, va="top", ha="right", fontsize=7, color="grey")
    ax_succ.legend(loc="upper left", fontsize=8)
    ax_ret.set_title(run_dir.name)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out
