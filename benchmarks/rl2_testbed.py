"""RL² on the meta-RL testbed (`tasks/point_mass/semicircle.yaml`: a point robot, a goal hidden on a
semicircle, reward only within 0.2 m of it) next to a memoryless PPO baseline: does RL² adapt?

    python benchmarks/rl2_testbed.py [--variants rl2 ppo] [--seeds 0 1 2] [--steps 2000000]
                                     [--chunk-steps 2000000] [--trials 50]

Each run's own periodic evaluation (every 100k steps: 50 trials, one per held-out goal, K = 5
episodes each from a fresh hidden state, mean actions) gives the curve: success at episode 1 and
at episode K of a trial vs env steps. At the end of a call the checkpoint is meta-tested again on
`--trials` held-out trials, with mean and with sampled actions (`meta_evaluate`, as
`rl2_ml1.py`). The goal (issue 21): episode K >= episode 1 + 0.3 on held-out goals within 2M
steps, every seed, while the memoryless baseline stays flat. Runs resume in chunks like the
other long benchmarks; finished runs keep their metrics and evaluations, not their checkpoints.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS, advance_run, chunked_parser, print_table, pyplot, save_figure, write_result  # noqa: E402
from benchmarks.rl2_ml1 import meta_evaluate  # noqa: E402
from taskforge.evaluation.report import after_a_miss  # noqa: E402
from taskforge.run import RunDir, read_jsonl  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = {
    "rl2": ROOT / "curricula/point_semicircle_rl2.yaml",
    "ppo": ROOT / "benchmarks/configs/point_semicircle_ppo.yaml",
}
RUNS = ROOT / "benchmarks/runs/rl2_testbed"
TRIAL_EPISODES = 5  # agents/rl2_testbed.yaml's K; the PPO baseline is evaluated over the same trials
GOAL_GAP = 0.3


def curve(run_dir: Path) -> list[dict]:
    """The run's periodic evaluations: step and success per episode of the trial. A memoryless
    run's evaluations are single episodes (its K is 1): one number, the same at every episode
    of a trial (the task has no randomisation, so its deterministic policy repeats itself)."""
    points = []
    for m in RunDir(run_dir).read_metrics():
        if "eval_episode/1" in m:
            points.append({"step": m["step"], "per_episode": [m[f"eval_episode/{k}"] for k in range(1, TRIAL_EPISODES + 1)]})
        elif "eval_success_rate" in m:
            points.append({"step": m["step"], "per_episode": [m["eval_success_rate"]]})
    return points


def first_adapted(points: list[dict]) -> int | None:
    """The first evaluated step at which episode K beat episode 1 by GOAL_GAP."""
    return next((p["step"] for p in points if p["per_episode"][-1] - p["per_episode"][0] >= GOAL_GAP), None)  # never for K = 1


def plot(runs: dict[str, dict], out: Path) -> Path:
    """Left: held-out success at episode 1 (dashed) and K (solid) vs steps, every seed. Right:
    the adaptation curve at each run's last meta-test."""
    plt = pyplot()
    fig, (ax, ax_adapt) = plt.subplots(1, 2, figsize=(11, 4), width_ratios=[3, 2])
    colours = dict(zip(VARIANTS, plt.rcParams["axes.prop_cycle"].by_key()["color"]))
    for name, run in runs.items():
        colour = colours[run["variant"]]
        steps = [p["step"] for p in run["curve"]]
        if run["curve"] and len(run["curve"][0]["per_episode"]) == 1:
            ax.plot(steps, [p["per_episode"][0] for p in run["curve"]], ":", color=colour, alpha=0.8, label=f"{name}, every episode")
        else:
            for k, style in ((0, "--"), (-1, "-")):
                label = f"{name}, episode {1 if k == 0 else TRIAL_EPISODES}"
                ax.plot(steps, [p["per_episode"][k] for p in run["curve"]], style, color=colour, alpha=0.8, label=label)
        if run["meta_test"]:
            ax_adapt.plot(range(1, TRIAL_EPISODES + 1), run["meta_test"]["per_episode"], "o-", color=colour, alpha=0.8, label=name)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("success on held-out goals")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(fontsize=6, handlelength=4, ncol=2)
    ax.set_title("point mass, goal hidden on a semicircle")
    ax_adapt.set_xticks(range(1, TRIAL_EPISODES + 1))
    ax_adapt.set_xlabel("episode of the trial")
    ax_adapt.set_ylim(-0.02, 1.02)
    ax_adapt.legend(fontsize=6)
    ax_adapt.set_title("adaptation curve at the end (mean actions)")
    return save_figure(fig, out)


def main() -> None:
    parser = chunked_parser(__doc__, chunk_steps=2_000_000)
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    parser.add_argument("--steps", type=int, default=2_000_000)
    parser.add_argument("--trials", type=int, default=50, help="held-out trials of the final meta-test (goal k for trial k)")
    args = parser.parse_args()

    runs = {}
    for variant in args.variants:
        for seed in args.seeds:
            run_dir = RUNS / f"{variant}-seed{seed}"
            run = RunDir(run_dir)
            if not args.report_only:
                start = time.perf_counter()
                step = advance_run(VARIANTS[variant], run_dir, seed, args.steps, args.chunk_steps)
                for sampled in (False, True):
                    meta_evaluate(run_dir, step, args.trials, sampled, trial_episodes=TRIAL_EPISODES, splits=("test",))
                print(f"{variant} seed {seed}: {step:,} / {args.steps:,} steps ({time.perf_counter() - start:.0f} s this call)", flush=True)
            if not run.metrics.exists():
                continue
            evals = [e for e in read_jsonl(run_dir / "meta_evals.jsonl") if e["trials"] == args.trials and e["split"] == "test"]
            last = max((e["step"] for e in evals), default=None)
            pick = {e.get("sampled", False): e for e in evals if e["step"] == last}
            points = curve(run_dir)
            runs[f"{variant}-seed{seed}"] = {
                "variant": variant, "seed": seed, "steps_done": run.steps_done(), "curve": points,
                "first_adapted_step": first_adapted(points), "meta_test": pick.get(False), "meta_test_sampled": pick.get(True),
                "steps_per_s": float(np.median([m["steps_per_s"] for m in run.read_metrics() if "steps_per_s" in m])),
            }

    rows = []
    for name, run in runs.items():
        ends = {key: run[key]["per_episode"] if run[key] else None for key in ("meta_test", "meta_test_sampled")}
        gap = None if ends["meta_test"] is None else ends["meta_test"][-1] - ends["meta_test"][0]
        rows.append([name, f"{run['steps_done']:,}",
                     *("-" if e is None else f"{e[0]:.2f} -> {e[-1]:.2f}" for e in ends.values()),
                     "-" if gap is None else f"{gap:+.2f}", after_a_miss((run["meta_test"] or {}).get("after_first_episode")),
                     "-" if run["first_adapted_step"] is None else f"{run['first_adapted_step']:,}", f"{run['steps_per_s']:,.0f}"])
    episodes = f"ep 1 -> {TRIAL_EPISODES}"
    print_table(["run", "env steps", f"meta-test {episodes}", f"sampled {episodes}", "gap (mean actions)", "later, after a miss",
                 f"first eval with gap >= {GOAL_GAP}", "steps/s"], rows)
    rl2 = [r for r in runs.values() if r["variant"] == "rl2" and r["meta_test"]]
    met = len(rl2) == len(args.seeds) and all(r["meta_test"]["per_episode"][-1] - r["meta_test"]["per_episode"][0] >= GOAL_GAP for r in rl2)
    print(f"goal (every RL² seed: episode {TRIAL_EPISODES} >= episode 1 + {GOAL_GAP} on held-out goals): {'met' if met else 'not met'}")
    print(f"curves: {plot(runs, RESULTS / 'rl2_testbed.png')}")
    remaining = sum(max(0, args.steps - r["steps_done"]) for r in runs.values())
    remaining += (len(args.variants) * len(args.seeds) - len(runs)) * args.steps
    write_result("rl2_testbed", {"variants": args.variants, "seeds": args.seeds, "steps": args.steps, "trials": args.trials,
                                 "trial_episodes": TRIAL_EPISODES, "goal_gap": GOAL_GAP, "goal_met": met, "runs": runs,
                                 "remaining_steps": remaining, "complete": remaining == 0})


if __name__ == "__main__":
    main()
