"""`taskforge plot`: learning curves (return, success) from a run's metrics.jsonl, with the
curriculum's promotions marked as vertical lines; or adaptation curves (success per episode of
the trial, with 95 % Wilson bands) from `taskforge eval` reports."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # no display on training machines
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from taskforge.run import RunDir  # noqa: E402
from taskforge.spec import SpecError  # noqa: E402


def plot_run(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """`RUN_DIR/curves.png` (or `out`): see `run_figure`."""
    return _save(run_figure(run_dir), Path(out) if out else RunDir(run_dir).curves)


def run_figure(run_dir: str | Path) -> Figure:
    """Return and success of the training episodes over env steps, the periodic evaluation, and
    the curriculum's promotions. The legend says what each success curve measures: the training
    curve follows whichever stage is being trained, the evaluation measures one fixed stage on
    the evaluation split, so the two differ on purpose."""
    run = RunDir(run_dir)
    metrics = run.read_metrics()
    if not metrics:
        raise SpecError.single(run.path, "", f"no {run.metrics.name} with records; expected a taskforge run directory")
    events = [e for e in run.read_events() if "to_stage" in e]  # promotions and demotions

    per_task = sorted({k for m in metrics for k in m if k.startswith("eval/")})  # `evaluation.tasks: all`
    fig, axes = plt.subplots(3 if per_task else 2, 1, figsize=(9, 9 if per_task else 6), sharex=True)
    ax_ret, ax_succ = axes[0], axes[1]
    rows = [m for m in metrics if m.get("return_mean") is not None]
    ax_ret.plot([m["step"] for m in rows], [m["return_mean"] for m in rows], lw=1)
    ax_ret.set_ylabel("episode return (train)")
    rows = [m for m in metrics if m.get("success_rate") is not None]
    stages = list(dict.fromkeys(m["stage"] for m in rows if "stage" in m))
    trained = f"the stage being trained ({' → '.join(stages)})" if len(stages) > 1 else f"stage {stages[0]}" if stages else "training"
    ax_succ.plot([m["step"] for m in rows], [m["success_rate"] for m in rows], lw=1,
                 label=f"training episodes, train goals: {trained}")
    evals = [m for m in metrics if "eval_success_rate" in m]
    if evals:
        ev = _evaluation_settings(run)
        label = f"evaluation, {ev['split']} goals: stage {ev['stage']}" if ev else "evaluation"
        label += f", mean over {len(per_task)} tasks" if per_task else ""
        ax_succ.plot([m["step"] for m in evals], [m["eval_success_rate"] for m in evals], "o-", label=label)
    ax_succ.set_ylabel("success rate")
    ax_succ.set_ylim(-0.02, 1.02)
    if per_task:
        _per_task_curves(axes[2], metrics, per_task)
    axes[-1].set_xlabel("environment steps")
    for ax in axes:
        for e in events:
            ax.axvline(e["step"], color="grey", ls="--", lw=0.8)
    for e in events:
        ax_ret.annotate(f"{e['kind']} → {e['to_stage']}", (e["step"], 1.0), xycoords=("data", "axes fraction"),
                        rotation=90, va="top", ha="right", fontsize=7, color="grey")
    ax_succ.legend(loc="upper left", fontsize=8)
    ax_ret.set_title(run.path.name)
    return fig


def _per_task_curves(ax, metrics: list[dict[str, Any]], keys: list[str]) -> None:
    """One evaluation curve per task (`eval/<task>`): which task of a multi-task policy lags."""
    for key in keys:
        rows = [m for m in metrics if key in m]
        ax.plot([m["step"] for m in rows], [m[key] for m in rows], "o-", ms=3, lw=1, label=key.removeprefix("eval/"))
    ax.set_ylabel("evaluation success per task")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(loc="lower right", fontsize=7, ncol=2)


def _save(fig: Figure, out: Path) -> Path:
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def _evaluation_settings(run: RunDir) -> dict[str, str] | None:
    """Which split and stage the run's periodic evaluation measured (from its config.json), so
    the plot can say that it is not the stage the training curve is on."""
    try:
        config = json.loads(run.config.read_text())
    except (OSError, ValueError):
        return None
    ev = config.get("curriculum", {}).get("evaluation", {})
    last = config.get("phases", [{}])[-1].get("stages", ["?"])[-1]
    return {"split": ev.get("split", "test"), "stage": ev.get("stage") or f"{last} (at the end; the current stage before)"}


def _read_report(path: Path) -> dict[str, Any]:
    try:
        report = json.loads(path.read_text())
        report["rows"][0]["per_episode"]
    except FileNotFoundError:
        raise SpecError.single(path, "", "no such eval report") from None
    except (json.JSONDecodeError, KeyError, IndexError, TypeError):
        raise SpecError.single(path, "", "not a `taskforge eval --out` report with per-episode results") from None
    return report


def plot_adaptation(reports: list[Path], out: str | Path | None = None) -> Path:
    """Success rate vs episode index within the trial, one line per (report, task, stage): the
    meta-test adaptation curve. An RL² agent that adapts rises from episode 1 to K; a memoryless
    policy evaluated over the same trials stays flat."""
    return _save(adaptation_figure(reports), Path(out) if out else reports[0].parent / "adaptation.png")


def adaptation_figure(reports: list[Path]) -> Figure:
    """See `plot_adaptation`; reports of one-episode trials have no curve: bars instead."""
    loaded = [(path, _read_report(path)) for path in reports]
    if all(len(row["per_episode"]) == 1 for _, report in loaded for row in report["rows"]):
        return _success_bars(loaded)
    fig, ax = plt.subplots(figsize=(7, 4))
    for path, report in loaded:
        for row in report["rows"]:
            episodes = [e["episode"] for e in row["per_episode"]]
            rates = [e["success_rate"] for e in row["per_episode"]]
            low = [e["success_ci95"][0] for e in row["per_episode"]]
            high = [e["success_ci95"][1] for e in row["per_episode"]]
            label = f"{report.get('algo', '?')} · {row['task']}:{row['stage']} ({path.stem})"
            (line,) = ax.plot(episodes, rates, "o-", label=label)
            ax.fill_between(episodes, low, high, color=line.get_color(), alpha=0.15)
    ax.set_xlabel("episode within the trial")
    ax.set_ylabel(f"success rate ({loaded[0][1]['split']} goals)")
    ax.set_ylim(-0.02, 1.02)
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.legend(loc="best", fontsize=8)
    ax.set_title("meta-test adaptation (95 % Wilson bands)")
    return fig


def _success_bars(loaded: list[tuple[Path, dict[str, Any]]]) -> Figure:
    """Reports of one-episode trials have no adaptation curve: one bar per (report, task, stage)
    with its 95 % Wilson interval instead of a line over a single x."""
    labels, rates, errors = [], [], [[], []]
    for path, report in loaded:
        for row in report["rows"]:
            labels.append(f"{report.get('algo', '?')} · {row['task']}:{row['stage']}\n({path.stem})")
            rates.append(row["success_rate"])
            errors[0].append(row["success_rate"] - row["success_ci95"][0])
            errors[1].append(row["success_ci95"][1] - row["success_rate"])
    fig, ax = plt.subplots(figsize=(max(4, 1.6 * len(labels)), 4))
    ax.bar(range(len(labels)), rates, yerr=errors, capsize=4, color="tab:blue", alpha=0.8)
    ax.set_xticks(range(len(labels)), labels, fontsize=7)
    ax.set_ylabel(f"success rate ({loaded[0][1]['split']} goals)")
    ax.set_ylim(0, 1.02)
    ax.set_title("one episode per trial: no adaptation curve (95 % Wilson intervals)")
    return fig
