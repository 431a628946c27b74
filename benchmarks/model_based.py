"""Model-based MPC (`algo: mpc`, agents/mpc.yaml) next to taskforge PPO at the same env steps, on
Meta-World with the goal observable: held-out success vs env steps, and wall-clock per env step.

    python benchmarks/model_based.py [--variants mpc-reach ppo-reach ...] [--seeds 0 1 2]
                                     [--chunk-steps 50000] [--report-only]

Variants (benchmarks/configs/, one file each) and the goals of issue 23:
- `mpc-reach` / `ppo-reach`: reach, 50k steps; MPC >= 0.90 held-out within 50k;
- `mpc-push` / `ppo-push`: push, 200k; MPC >= 0.95 within 200k; `mpc-push-value` the same with
  a terminal value at the plan's end (agents/mpc_value.yaml), `mpc-push-large` with that value and
  a 3 x 256 ensemble (agents/mpc_large.yaml), `mpc-push-optimism` that scoring plans with one
  std of optimism about the ensemble's disagreement (agents/mpc_optimistic.yaml), `mpc-push-only`
  the large preset on the push stage alone, without reach before it, `mpc-push-demos` that with
  10 scripted pushes seeding the model's data, `mpc-push-beta-refit` the large preset with the
  model fitted by β-NLL and the value refitted afresh every 50k (agents/mpc_beta_refit.yaml),
  `mpc-push-heads-refit` that with the value as the mean of 5 bootstrapped heads
  (agents/mpc_heads_refit.yaml), `mpc-push-policy-value` that with TD-MPC's value, Q(s, pi(s))
  of a policy fitted by TD3+BC, fitted afresh at its first fit only, and pi's rollouts proposed
  (agents/mpc_policy_value.yaml), `mpc-push-policy-value-refit` that with the value refitted
  afresh every 50k as well (agents/mpc_policy_value_refit.yaml: the record of why not),
  `mpc-push-policy-value-bounded` the policy value with its TD targets clipped to the rows'
  reward range over (1 - discount) (agents/mpc_policy_value_bounded.yaml),
  `mpc-push-policy-value-late` that with the value's first fit at 20k env steps, plans scoring
  rewards alone before it (agents/mpc_policy_value_late.yaml), `mpc-push-policy-value-relabel`
  that with the value also fitting reach's rows, relabelled with push's reward by the model's
  reward network, and a first fit of 20k steps (agents/mpc_policy_value_relabel.yaml),
  `mpc-push-policy-value-utd` the policy value fitted one TD3+BC step per env step, its first
  fit 1,000 steps (agents/mpc_policy_value_utd.yaml), `mpc-push-policy-value-long` that planning
  20 steps ahead instead of 10 (agents/mpc_policy_value_long.yaml),
  `mpc-push-policy-value-long-demos` that with 10 scripted pushes seeding the model's data;
  `mpc-push-policy-value-long-demos-fresh` that trained on a fresh (puck, goal) pair every
  episode instead of ML1's 50 training pairs (`goals.train.draw: fresh`);
- `mpc-pick-place`: pick-place `place` from scratch, 1M; >= 0.80 within 1M (PPO from scratch:
  0.00 at 2M, benchmarks/pick_place_curriculum.py); `mpc-pick-place-native` the same in TD-MPC2's
  setting: Meta-World's own reward, no randomisation (configs/pick_place_native.yaml);
  `mpc-pick-place-native-beta` that with the model fitted by β-NLL (agents/mpc_beta.yaml: under
  PETS's plain likelihood the native run's model never learnt the puck's motion);
  `mpc-pick-place-native-beta-refit` a branch of that run at 400k (its model, value and data)
  going on with the value refitted afresh every 50k steps (agents/mpc_beta_refit.yaml); its
  snapshot is `runs/model_based/branch_points/mpc-pick-place-native-beta-seed<seed>-400k/`, a copy
  of that run's checkpoint at 400k, local like every checkpoint;
- `mpc-pick-place-demos`: the same with 50 scripted episodes seeding the model, 100k; >= 0.95
  within 100k (PPO with demos: benchmarks/warm_start.py); `mpc-pick-place-demos-prior` the same
  with a policy cloned from the demos proposing plans (agents/mpc_demos.yaml).
Each run's own evaluations (50 held-out ML1 goals) give the curve. Anchors (TD-MPC2's result
files, 3 seeds, state observations): reach 0.63 at 100k and 0.97 at 1M; push 0.97 at 200k and
0.90 at 1M; pick-place 0.63 at 200k and 0.83 at 1M. Runs resume in chunks like the other long
benchmarks; finished runs keep their metrics, not their checkpoints (which hold the model's data).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS, advance_run, chunked_parser, print_table, pyplot, save_figure, write_result  # noqa: E402
from taskforge.run import RunDir  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "benchmarks/configs"
RUNS = ROOT / "benchmarks/runs/model_based"


@dataclass(frozen=True)
class Variant:
    """One row of the benchmark: its config (benchmarks/configs/), the task its plot panel shows,
    the stage its held-out success is read on (a push run evaluates `reach` until it is promoted;
    those points are not push's curve), its budget in env steps and issue 23's held-out goal
    (None for the PPO references). A branch (`branched_at` > 0) starts from a snapshot of
    another run at that many env steps (its config's `init_from`: model, value and data); its
    steps, curve and budget count from the snapshot's, so it plots beside the run it left."""

    task: str
    stage: str
    budget: int
    goal: float | None
    branched_at: int = 0

    def config(self, name: str) -> Path:
        """The variant's config file: its name with underscores (`mpc-push` -> `mpc_push.yaml`)."""
        return CONFIGS / f"{name.replace('-', '_')}.yaml"


VARIANTS: dict[str, Variant] = {
    "mpc-reach": Variant("reach", "reach", 50_000, 0.90),
    "ppo-reach": Variant("reach", "reach", 50_000, None),
    "mpc-push": Variant("push", "push", 200_000, 0.95),
    "mpc-push-value": Variant("push", "push", 200_000, 0.95),
    "mpc-push-large": Variant("push", "push", 200_000, 0.95),
    "mpc-push-optimism": Variant("push", "push", 200_000, 0.95),
    "mpc-push-only": Variant("push", "push", 200_000, 0.95),
    "mpc-push-demos": Variant("push", "push", 200_000, 0.95),
    "mpc-push-beta-refit": Variant("push", "push", 200_000, 0.95),
    "mpc-push-heads-refit": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value-refit": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value-bounded": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value-late": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value-relabel": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value-utd": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value-long": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value-long-demos": Variant("push", "push", 200_000, 0.95),
    "mpc-push-policy-value-long-demos-fresh": Variant("push", "push", 200_000, 0.95),
    "ppo-push": Variant("push", "push", 200_000, None),
    "mpc-pick-place": Variant("pick-place", "place", 1_000_000, 0.80),
    "mpc-pick-place-native": Variant("pick-place", "place", 1_000_000, 0.80),
    "mpc-pick-place-native-beta": Variant("pick-place", "place", 1_000_000, 0.80),
    "mpc-pick-place-native-beta-refit": Variant("pick-place", "place", 1_000_000, 0.80, branched_at=400_000),
    "mpc-pick-place-demos": Variant("pick-place", "place", 100_000, 0.95),
    "mpc-pick-place-demos-prior": Variant("pick-place", "place", 100_000, 0.95),
}


def curve(metrics: list[dict], stage: str) -> list[tuple[int, float]]:
    """(step, held-out success) of a run's evaluations on `stage` (an evaluation runs on the stage
    being trained, which its metrics record names). The committed pick-place runs with demos were
    logged before the trainer named the stage of its evaluation right after pretraining; that row
    is on the run's first stage."""
    first = next((m["stage"] for m in metrics if "stage" in m), None)
    return [(m["step"], m["eval_success_rate"]) for m in metrics
            if "eval_success_rate" in m and m.get("stage", first) == stage]


def summary(variant: str, seed: int, run_dir: Path) -> dict:
    """What the table, the plot and the JSON say about one run: its curve, best and last held-out
    success, the first evaluation at the goal and the median training wall-clock per env step."""
    run, spec = RunDir(run_dir), VARIANTS[variant]
    metrics = run.read_metrics()
    rates = [m["steps_per_s"] for m in metrics if "steps_per_s" in m]
    points = [(step + spec.branched_at, success) for step, success in curve(metrics, spec.stage)]
    return {
        "variant": variant, "seed": seed, "steps_done": run.steps_done() + spec.branched_at, "budget": spec.budget, "curve": points,
        "best": max((s for _, s in points), default=None), "end": points[-1][1] if points else None,
        "first_at_goal": next((step for step, s in points if spec.goal is not None and s >= spec.goal), None),
        "ms_per_env_step": 1000.0 / float(np.median(rates)) if rates else None,
    }


def runs_on_disk() -> dict[str, dict]:
    """Every variant's runs that have metrics, whichever this call trained: the report (JSON, PNG)
    is the whole benchmark, so a chunk of one run does not drop the others from it."""
    runs = {}
    for variant in VARIANTS:
        seeds = sorted(int(d.name.rsplit("seed", 1)[1]) for d in RUNS.glob(f"{variant}-seed*"))
        for seed in seeds:
            run_dir = RUNS / f"{variant}-seed{seed}"
            if RunDir(run_dir).metrics.exists():
                runs[run_dir.name] = summary(variant, seed, run_dir)
    return runs


def plot(runs: dict[str, dict], out: Path) -> Path:
    """One panel per task: every run's held-out success vs env steps, MPC solid, PPO dashed."""
    plt = pyplot()
    tasks = list(dict.fromkeys(VARIANTS[r["variant"]].task for r in runs.values()))
    fig, axes = plt.subplots(1, max(len(tasks), 1), figsize=(4.5 * max(len(tasks), 1), 3.5), squeeze=False)
    for ax, task in zip(axes[0], tasks):
        for name, run in runs.items():
            if VARIANTS[run["variant"]].task == task and run["curve"]:
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
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS),
                        help="the runs to advance (the report always covers every run on disk)")
    args = parser.parse_args()
    if not args.report_only:
        for variant in args.variants:
            for seed in args.seeds:
                start = time.perf_counter()
                spec = VARIANTS[variant]
                own = advance_run(spec.config(variant), RUNS / f"{variant}-seed{seed}", seed, spec.budget - spec.branched_at, args.chunk_steps)
                print(f"{variant} seed {seed}: {own + spec.branched_at:,} / {spec.budget:,} steps ({time.perf_counter() - start:.0f} s this call)",
                      flush=True)
    runs = runs_on_disk()
    rows = [[name, f"{r['steps_done']:,} / {r['budget']:,}", "-" if r["end"] is None else f"{r['end']:.2f}",
             "-" if r["best"] is None else f"{r['best']:.2f}",
             "-" if r["first_at_goal"] is None else f"{r['first_at_goal']:,}",
             "-" if r["ms_per_env_step"] is None else f"{r['ms_per_env_step']:.2f}"] for name, r in runs.items()]
    print_table(["run", "env steps", "held-out at the end", "best", "first at the goal", "ms per env step (train)"], rows)
    print(f"curves: {plot(runs, RESULTS / 'model_based.png')}")
    write_result("model_based", {"advanced": [] if args.report_only else args.variants,
                                 "seeds_advanced": [] if args.report_only else args.seeds,
                                 "budgets": {v: s.budget for v, s in VARIANTS.items()},
                                 "goals": {v: s.goal for v, s in VARIANTS.items() if s.goal is not None}, "runs": runs})


if __name__ == "__main__":
    main()
