"""Model-based MPC (`algo: mpc`, agents/mpc.yaml) next to taskforge PPO at the same env steps, on
Meta-World with the goal observable: held-out success vs env steps, and wall-clock per env step.

    python benchmarks/model_based.py [--variants mpc-reach ppo-reach ...] [--seeds 0 1 2]
                                     [--chunk-steps 50000] [--report-only]

Variants (benchmarks/configs/, one file each) and the goals of issue 23:
- `mpc-reach` / `ppo-reach`: reach, 50k steps; MPC >= 0.90 held-out within 50k;
- `mpc-push` / `ppo-push`: push, 200k; MPC >= 0.95 within 200k; `mpc-push-value` the same with
  a terminal value at the plan's end (agents/mpc_value.yaml), `mpc-push-large` with that value and
  a 3 x 256 ensemble (agents/mpc_large.yaml);
- `mpc-pick-place`: pick-place `place` from scratch, 1M; >= 0.80 within 1M (PPO from scratch:
  0.00 at 2M, benchmarks/pick_place_curriculum.py);
- `mpc-pick-place-demos`: the same with 50 scripted episodes seeding the model, 100k; >= 0.95
  within 100k (PPO with demos: benchmarks/warm_start.py).
Each run's own evaluations (50 held-out ML1 goals) give the curve. Anchors (TD-MPC2's result
files, 3 seeds, state observations): reach 0.63 at 100k and 0.97 at 1M; push 0.97 at 200k and
0.90 at 1M; pick-place 0.63 at 200k and 0.83 at 1M. Runs resume in chunks like the other long
benchmarks; finished runs keep their metrics, not their checkpoints (which hold the model's data).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS, advance_run, chunked_parser, print_table, pyplot, save_figure, write_result  # noqa: E402
from taskforge.run import RunDir  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "benchmarks/configs"
VARIANTS = {name: CONFIGS / f"{name.replace('-', '_')}.yaml" for name in (
    "mpc-reach", "ppo-reach", "mpc-push", "mpc-push-value", "mpc-push-large", "ppo-push", "mpc-pick-place", "mpc-pick-place-demos")}
BUDGET = {"mpc-reach": 50_000, "ppo-reach": 50_000, "mpc-push": 200_000, "mpc-push-value": 200_000, "mpc-push-large": 200_000,
          "ppo-push": 200_000, "mpc-pick-place": 1_000_000, "mpc-pick-place-demos": 100_000}
GOAL = {"mpc-reach": 0.90, "mpc-push": 0.95, "mpc-push-value": 0.95, "mpc-push-large": 0.95,
        "mpc-pick-place": 0.80, "mpc-pick-place-demos": 0.95}
RUNS = ROOT / "benchmarks/runs/model_based"


def curve(run_dir: Path) -> list[tuple[int, float]]:
    """(step, held-out success) of the run's periodic evaluations."""
    return [(m["step"], m["eval_success_rate"]) for m in RunDir(run_dir).read_metrics() if "eval_success_rate" in m]


def task_of(variant: str) -> str:
    """The task a variant runs (`mpc-push-value`, `mpc-push-large` -> `push`): one plot panel each."""
    return variant.split("-", 1)[1].removesuffix("-value").removesuffix("-large")


def plot(runs: dict[str, dict], out: Path) -> Path:
    """One panel per task: every run's held-out success vs env steps, MPC solid, PPO dashed."""
    plt = pyplot()
    tasks = sorted({task_of(r["variant"]) for r in runs.values()})
    fig, axes = plt.subplots(1, max(len(tasks), 1), figsize=(4.5 * max(len(tasks), 1), 3.5), squeeze=False)
    for ax, task in zip(axes[0], tasks):
        for name, run in runs.items():
            if task_of(run["variant"]) == task and run["curve"]:
                steps, success = zip(*run["curve"])
                ax.plot(steps, success, "-" if run["variant"].startswith("mpc") else "--", marker=".", label=name)
        ax.set_title(task)
        ax.set_xlabel("env steps")
        ax.set_ylim(-0.02, 1.02)
        ax.legend(fontsize=6)
    axes[0][0].set_ylabel("held-out success (50 ML1 goals)")
    return save_figure(fig, out)


def main() -> None:
    parser = chunked_parser(__doc__, chunk_steps=50_000)
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    args = parser.parse_args()
    runs = {}
    for variant in args.variants:
        for seed in args.seeds:
            run_dir = RUNS / f"{variant}-seed{seed}"
            if not args.report_only:
                start = time.perf_counter()
                step = advance_run(VARIANTS[variant], run_dir, seed, BUDGET[variant], args.chunk_steps)
                print(f"{variant} seed {seed}: {step:,} / {BUDGET[variant]:,} steps ({time.perf_counter() - start:.0f} s this call)",
                      flush=True)
            run = RunDir(run_dir)
            if not run.metrics.exists():
                continue
            rates = [m["steps_per_s"] for m in run.read_metrics() if "steps_per_s" in m]
            points = curve(run_dir)
            goal = GOAL.get(variant)
            runs[f"{variant}-seed{seed}"] = {
                "variant": variant, "seed": seed, "steps_done": run.steps_done(), "budget": BUDGET[variant], "curve": points,
                "best": max((s for _, s in points), default=None), "end": points[-1][1] if points else None,
                "first_at_goal": next((step for step, s in points if goal is not None and s >= goal), None),
                "ms_per_env_step": 1000.0 / float(np.median(rates)) if rates else None,
            }
    rows = [[name, f"{r['steps_done']:,} / {r['budget']:,}", "-" if r["end"] is None else f"{r['end']:.2f}",
             "-" if r["best"] is None else f"{r['best']:.2f}",
             "-" if r["first_at_goal"] is None else f"{r['first_at_goal']:,}",
             "-" if r["ms_per_env_step"] is None else f"{r['ms_per_env_step']:.2f}"] for name, r in runs.items()]
    print_table(["run", "env steps", "held-out at the end", "best", "first at the goal", "ms per env step (train)"], rows)
    print(f"curves: {plot(runs, RESULTS / 'model_based.png')}")
    write_result("model_based", {"variants": args.variants, "seeds": args.seeds, "budgets": BUDGET, "goals": GOAL, "runs": runs})


if __name__ == "__main__":
    main()
