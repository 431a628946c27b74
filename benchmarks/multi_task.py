"""One policy across tasks: Meta-World MT10 warm-started from Meta-World's scripted policies vs the
same agent from scratch, and one xArm7 policy through the pick-place variants; held-out success of
every task vs env steps, several seeds.

    python benchmarks/multi_task.py --variants mt10-warm mt10-scratch xarm7-variants [--seeds 0 1 2] [--chunk-steps 500000]
    python benchmarks/multi_task.py --report-only [--variants ...] [--seeds 0 1 2]

Variants (each a curriculum; its `evaluation: {tasks: all}` plays every task on its held-out goals):
- `mt10-warm`: curricula/mt10.yaml (2M env steps, the warm start's expert and DAgger steps counted);
- `mt10-scratch`: benchmarks/configs/mt10_scratch.yaml, the same without the warm start;
- `mt10-warm-reweighted`: benchmarks/configs/mt10_reweighted.yaml, `mt10-warm` with learning-progress
  sampling reweighted toward low success (`sampling.reweight: 0.1`), the sampler's ablation;
- `mt10-warm-400x3`: benchmarks/configs/mt10_400x3.yaml, `mt10-warm` with a 3 x 400 policy instead
  of 2 x 256, the capacity ablation;
- `mt10-warm-bc-decay`: benchmarks/configs/mt10_bc_decay.yaml, `mt10-warm` with DAPG's BC term
  decaying to 0 instead of held at 0.01, the regulariser's ablation;
- `xarm7-variants`: curricula/xarm7_variants.yaml (1M env steps): nominal -> big cube -> high goals
  -> low table with replay of the earlier variants.
The full budget (3 seeds of each: 15M env steps) spans sessions, so each call advances every run by
at most `--chunk-steps` (resuming from its checkpoint) and rewrites the report from what exists.
Goals (issue 20): MT10 average held-out success >= 0.95 and every task >= 0.80 within 2M env steps;
every xArm7 variant >= 0.90 within 1M.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS, advance_run, chunked_parser, print_table, pyplot, save_figure, write_result  # noqa: E402
from taskforge.run import RunDir  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VARIANTS: dict[str, tuple[Path, int]] = {
    "mt10-warm": (ROOT / "curricula/mt10.yaml", 2_000_000),
    "mt10-scratch": (ROOT / "benchmarks/configs/mt10_scratch.yaml", 2_000_000),
    "mt10-warm-reweighted": (ROOT / "benchmarks/configs/mt10_reweighted.yaml", 2_000_000),
    "mt10-warm-400x3": (ROOT / "benchmarks/configs/mt10_400x3.yaml", 2_000_000),
    "mt10-warm-bc-decay": (ROOT / "benchmarks/configs/mt10_bc_decay.yaml", 2_000_000),
    "xarm7-variants": (ROOT / "curricula/xarm7_variants.yaml", 1_000_000),
}
RUNS = ROOT / "benchmarks/runs/multi_task"
GOALS = {"mt10": {"mean": 0.95, "each": 0.80}, "xarm7": {"mean": 0.0, "each": 0.90}}


def run_record(variant: str, seed: int, run: RunDir) -> dict[str, Any]:
    """Every evaluation of a run: the step, the mean over tasks and each task's success."""
    evals = [m for m in run.read_metrics() if "eval_success_rate" in m]
    return {
        "variant": variant, "seed": seed, "steps_done": run.steps_done(), "promotions": run.stage_changes(),
        "evaluations": [{"step": m["step"], "mean": m["eval_success_rate"],
                         "tasks": {k.removeprefix("eval/"): v for k, v in m.items() if k.startswith("eval/")}} for m in evals],
    }


def last_evaluation(record: dict[str, Any]) -> dict[str, Any] | None:
    return record["evaluations"][-1] if record["evaluations"] else None


def verdict(variant: str, records: list[dict[str, Any]], total: int) -> str:
    """The issue's goal for a variant, on the last evaluation of each seed that finished: met
    where every finished seed meets it; how many do is said either way."""
    finished = [r for r in records if r["steps_done"] >= total and r["evaluations"]]
    if not finished:
        return "not finished"
    goal = GOALS[variant.split("-")[0]]
    ends = [last_evaluation(r) for r in finished]
    passed = sum(e["mean"] >= goal["mean"] and min(e["tasks"].values() or [e["mean"]]) >= goal["each"] for e in ends if e)
    rule = (f"mean >= {goal['mean']}, " if goal["mean"] else "") + f"every task >= {goal['each']}"
    return f"{'met' if passed == len(finished) else 'not met'}: {passed} of {len(finished)} finished seed(s) ({rule})"


def plot(records: dict[str, dict[str, Any]], variants: list[str], out: Path) -> Path:
    """Per variant: the mean over tasks of each seed (thin) and over seeds (thick), and each task's
    mean over seeds (dotted), vs env steps."""
    plt = pyplot()
    fig, axes = plt.subplots(len(variants), 1, figsize=(9, 3.6 * len(variants)), squeeze=False)
    for ax, variant in zip(axes[:, 0], variants):
        runs = [r for r in records.values() if r["variant"] == variant]
        for r in runs:
            ax.plot([e["step"] for e in r["evaluations"]], [e["mean"] for e in r["evaluations"]], color="black", lw=0.6, alpha=0.4)
        steps = sorted({e["step"] for r in runs for e in r["evaluations"]})
        if steps:
            ax.plot(steps, [np.mean([e["mean"] for r in runs for e in r["evaluations"] if e["step"] == s]) for s in steps],
                    "o-", color="black", lw=2, label=f"mean over tasks ({len(runs)} seed{'s' * (len(runs) > 1)})")
        tasks = sorted({t for r in runs for e in r["evaluations"] for t in e["tasks"]})
        for task in tasks:
            ys = [np.mean([e["tasks"][task] for r in runs for e in r["evaluations"] if e["step"] == s and task in e["tasks"]]) for s in steps]
            ax.plot(steps, ys, ":", lw=1, label=task)
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel("held-out success")
        ax.set_title(variant if runs else f"{variant} (no run yet)")
        if runs:
            ax.legend(loc="lower right", fontsize=6, ncol=2)
    axes[-1, 0].set_xlabel("environment steps (expert steps included)")
    return save_figure(fig, out)


def main() -> None:
    parser = chunked_parser(__doc__, chunk_steps=500_000)
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    args = parser.parse_args()

    records: dict[str, dict[str, Any]] = {}
    for variant in args.variants:
        curriculum, total = VARIANTS[variant]
        for seed in args.seeds:
            run_dir = RUNS / f"{variant}-seed{seed}"
            run = RunDir(run_dir)
            if not args.report_only:
                start = time.perf_counter()
                step = advance_run(curriculum, run_dir, seed, total, args.chunk_steps)
                print(f"{variant} seed {seed}: {step:,} / {total:,} steps ({time.perf_counter() - start:.0f} s this call)", flush=True)
            if run.metrics.exists():
                records[f"{variant}-seed{seed}"] = run_record(variant, seed, run)

    rows = []
    for key, r in records.items():
        end = last_evaluation(r)
        if end is None:
            continue
        weakest = min(end["tasks"].items(), key=lambda kv: kv[1]) if end["tasks"] else ("-", end["mean"])
        rows.append([key, f"{r['steps_done']:,}", f"{end['step']:,}", f"{end['mean']:.2f}", f"{weakest[0]} {weakest[1]:.2f}"])
    print_table(["run", "steps", "last evaluation at", "held-out success, mean over tasks", "weakest task"], rows)
    per_task = {}
    for variant in args.variants:
        ends = [e for r in records.values() if r["variant"] == variant and (e := last_evaluation(r))]
        tasks = sorted({t for e in ends for t in e["tasks"]})
        per_task[variant] = {t: float(np.mean([e["tasks"][t] for e in ends if t in e["tasks"]])) for t in tasks}
        if tasks:
            print(f"\n{variant}, last evaluation, mean over seeds:")
            print_table(["task", "held-out success"], [[t, f"{v:.2f}"] for t, v in per_task[variant].items()])
    verdicts = {v: verdict(v, [r for r in records.values() if r["variant"] == v], VARIANTS[v][1]) for v in args.variants}
    for variant, line in verdicts.items():
        print(f"goal, {variant}: {line}")
    remaining = sum(max(0, VARIANTS[v][1] - records.get(f"{v}-seed{s}", {"steps_done": 0})["steps_done"])
                    for v in args.variants for s in args.seeds)
    print(f"remaining: {remaining:,} env steps")
    if records:
        print(f"curves: {plot(records, args.variants, RESULTS / 'multi_task.png')}")
    write_result("multi_task", {"variants": args.variants, "seeds": args.seeds, "runs": records, "last_per_task": per_task,
                                "goals": verdicts, "remaining_steps": remaining, "complete": remaining == 0})


if __name__ == "__main__":
    main()
