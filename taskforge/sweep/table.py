"""A sweep's results in the form of Learning Dexterity's ablation tables (OpenAI et al. 2018,
Table 3 "different training environments compared"): one row per training environment, one
column per test condition, each cell the mean over seeds ± a 95 % confidence interval, the
median, and every seed's result sorted, so a reader sees the spread and not only a mean. Written
as Markdown and JSON, with learning curves per variant as a PNG."""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from taskforge.machine import machine
from taskforge.run import RunDir, read_jsonl, save_json
from taskforge.sweep.plan import SweepPlan


def summarize_seeds(values: Sequence[float]) -> dict[str, Any]:
    """Mean, its 95 % confidence interval (Student's t over seeds: with 3 seeds the half-width is
    2.48 standard deviations, as wide as 3 seeds honestly allow; none with one seed), median and
    the sorted values."""
    n = len(values)
    mean = float(np.mean(values))
    half = float(stats.t.ppf(0.975, n - 1) * np.std(values, ddof=1) / np.sqrt(n)) if n > 1 else None
    return {"seeds": n, "mean": mean, "ci95_half_width": half, "median": float(statistics.median(values)),
            "sorted": sorted(float(v) for v in values)}


def sweep_table(plan: SweepPlan, records: list[dict[str, Any]], command: str) -> dict[str, Any]:
    """The table as data: per variant and condition, the seeds' held-out success rates."""
    rows = []
    for variant in plan.variant_names():
        mine = sorted((r for r in records if r["variant"] == variant), key=lambda r: r["seed"])
        cells = {}
        for condition in (c.name for c in plan.conditions):
            per_seed = {r["seed"]: r["conditions"][condition]["success_rate"] for r in mine}
            cells[condition] = {"per_seed": per_seed, **(summarize_seeds(list(per_seed.values())) if per_seed else {})}
        rows.append({"variant": variant, "steps": sorted({r["step"] for r in mine}), "cells": cells})
    ev = plan.spec.evaluation
    return {
        "sweep": plan.spec.name,
        "file": str(plan.file),
        "command": command,
        "machine": machine(),
        "metric": f"success rate of stage '{plan.stage}', {ev.episodes} episodes on the {ev.split} goals, mean actions",
        "conditions": [c.name for c in plan.conditions],
        "seeds": plan.spec.seeds,
        "rows": rows,
    }


def format_cell(cell: dict[str, Any]) -> str:
    """`0.81 ± 0.12 (median 0.84; 0.70 0.84 0.90)`, or `-` for a variant with no finished seed."""
    if not cell.get("seeds"):
        return "-"
    spread = "" if cell["ci95_half_width"] is None else f" ± {cell['ci95_half_width']:.2f}"
    values = " ".join(f"{v:.2f}" for v in cell["sorted"])
    return f"{cell['mean']:.2f}{spread} (median {cell['median']:.2f}; {values})"


def format_markdown(table: dict[str, Any]) -> str:
    lines = [
        f"# Sweep `{table['sweep']}`",
        "",
        f"Each cell: {table['metric']}; mean over seeds ± 95 % CI (Student's t), median, and each seed's "
        "result sorted.",
        "",
        "| training environment | " + " | ".join(table["conditions"]) + " |",
        "|---|" + "---|" * len(table["conditions"]),
    ]
    for row in table["rows"]:
        lines.append(f"| {row['variant']} | " + " | ".join(format_cell(row["cells"][c]) for c in table["conditions"]) + " |")
    m = table["machine"]
    lines += ["", f"Command: `{table['command']}`; machine: {m['cpu']}, {m['cores']} cores ({m['host_label']})."]
    return "\n".join(lines) + "\n"


def plot_curves(plan: SweepPlan, out: Path) -> Path:
    """Held-out success (the curriculum's own evaluations) against env steps: each variant's mean
    over its seeds, the band between its worst and best seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for variant in plan.variant_names():
        curves = []
        for trial in (t for t in plan.trials if t.variant == variant):
            run = RunDir(trial.run_dir)
            points = [(m["step"], m["eval_success_rate"]) for m in read_jsonl(run.metrics) if "eval_success_rate" in m] \
                if run.metrics.is_file() else []
            if points:
                curves.append(dict(points))
        if not curves:
            continue
        steps = sorted(set.intersection(*(set(c) for c in curves)))
        values = np.array([[c[s] for s in steps] for c in curves])
        line, = ax.plot(steps, values.mean(axis=0), label=f"{variant} ({len(curves)} seeds)")
        ax.fill_between(steps, values.min(axis=0), values.max(axis=0), color=line.get_color(), alpha=0.15)
    ax.set_xlabel("env steps")
    ax.set_ylabel("held-out success (training's evaluations)")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(f"sweep {plan.spec.name}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def write_tables(plan: SweepPlan, table: dict[str, Any]) -> list[Path]:
    """`table.md`, `table.json` and `curves.png` in the sweep's folder."""
    md, js, png = plan.out / "table.md", plan.out / "table.json", plan.out / "curves.png"
    md.write_text(format_markdown(table))
    save_json(table, js)
    return [md, js, plot_curves(plan, png)]

