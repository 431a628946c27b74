"""Meta-World pick-place without demos, goal observable: the 4-stage curriculum vs flat training
on the `place` stage, several seeds, success on held-out (ML1 test) goals vs env steps.

    python benchmarks/pick_place_curriculum.py [--seeds 0 1 2] [--steps 2000000] [--chunk-steps 200000]

The full budget (2 variants x 3 seeds x 2M steps) takes many hours on 2 cores, so the script
works in chunks: each call advances every run by at most `--chunk-steps` (resuming from its
checkpoint) and rewrites the result table from what exists so far. Run it again to continue.
Both variants evaluate the `place` stage on 20 held-out goals every 100k steps (the curricula's
`evaluation` settings), so their curves measure the same thing. The curves (per seed and mean,
with the curriculum's stage over time) go to `results/pick_place_curriculum.png`.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS, advance_run, chunked_parser, print_table, pyplot, save_figure, write_result  # noqa: E402
from taskforge.envs import load_curriculum  # noqa: E402
from taskforge.run import RunDir  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = {"curriculum": ROOT / "benchmarks/configs/pick_place_scratch.yaml", "flat": ROOT / "benchmarks/configs/pick_place_flat.yaml"}
RUNS = ROOT / "benchmarks/runs/pick_place_scratch"
"""The goal-observable runs; the earlier hidden-goal ones (issue 3) are in runs/pick_place_hidden_goal."""


def plot_curves(runs: dict[str, dict], out: Path) -> Path:
    """Held-out `place` success vs env steps (thin: each seed, thick: the mean over the seeds that
    reached that evaluation) and, below, the stage each curriculum seed trained on."""
    plt = pyplot()

    stages = load_curriculum(VARIANTS["curriculum"]).phases[0].stages  # the y axis of the stage panel
    fig, (ax, ax_stage) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=[3, 1.2])
    for colour, variant in zip(("tab:blue", "tab:orange"), VARIANTS):
        curves = [dict(r["eval_place_success"]) for r in runs.values() if r["variant"] == variant]
        for curve in curves:
            ax.plot(list(curve), list(curve.values()), color=colour, lw=0.8, alpha=0.4)
        steps = sorted({s for c in curves for s in c})
        if steps:
            mean = [np.mean([c[s] for c in curves if s in c]) for s in steps]
            ax.plot(steps, mean, "o-", color=colour, lw=2, label=f"{variant} (mean of {len(curves)} seed{'s' * (len(curves) > 1)})")
    for r in runs.values():
        if r["variant"] == "curriculum":
            xs, ys = [0], [0]
            for step, stage in r["promotions"]:
                xs.append(step)
                ys.append(stages.index(stage))
            xs.append(r["steps_done"])
            ys.append(ys[-1])
            ax_stage.step(xs, ys, where="post", lw=1, label=f"seed {r['seed']}")
    ax.set_ylabel("held-out place success")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("Meta-World pick-place without demos: curriculum vs flat (ML1 test goals)")
    ax_stage.set_yticks(range(len(stages)), stages)
    ax_stage.set_ylabel("curriculum stage")
    ax_stage.set_xlabel("environment steps")
    ax_stage.legend(loc="lower right", fontsize=7)
    return save_figure(fig, out)


def main() -> None:
    parser = chunked_parser(__doc__, chunk_steps=200_000)
    parser.add_argument("--steps", type=int, default=2_000_000)
    args = parser.parse_args()

    runs = {}
    for seed in args.seeds:
        for variant in VARIANTS:
            run_dir = RUNS / f"{variant}-seed{seed}"
            run = RunDir(run_dir)
            if args.report_only:
                if not run.metrics.exists():
                    continue
                step = run.steps_done()
            else:
                start = time.perf_counter()
                step = advance_run(VARIANTS[variant], run_dir, seed, args.steps, args.chunk_steps)
                print(f"{variant} seed {seed}: {step:,} / {args.steps:,} steps ({time.perf_counter() - start:.0f} s this call)", flush=True)
            runs[f"{variant}-seed{seed}"] = {
                "variant": variant, "seed": seed, "steps_done": step,
                "eval_place_success": [(m["step"], m["eval_success_rate"]) for m in run.read_metrics() if "eval_success_rate" in m],
                "promotions": run.stage_changes(),
            }

    buckets = sorted({s // 100_000 * 100_000 for r in runs.values() for s, _ in r["eval_place_success"]})
    rows = []
    for b in buckets:
        row = [f"{b:,}"]
        for variant in VARIANTS:
            vals = [v for r in runs.values() if r["variant"] == variant for s, v in r["eval_place_success"] if s // 100_000 * 100_000 == b]
            row.append(f"{np.mean(vals):.2f} (n={len(vals)})" if vals else "-")
        rows.append(row)
    print_table(["env steps", "curriculum: held-out place success", "flat: held-out place success"], rows)
    missing = len(args.seeds) * len(VARIANTS) - len(runs)
    remaining = sum(max(0, args.steps - r["steps_done"]) for r in runs.values()) + missing * args.steps
    print(f"remaining: {remaining:,} env steps ({len(runs)} runs started, {missing} not started)")
    print(f"curves: {plot_curves(runs, RESULTS / 'pick_place_curriculum.png')}")
    write_result("pick_place_curriculum", {"seeds": args.seeds, "steps": args.steps, "runs": runs, "remaining_steps": remaining,
                                           "complete": remaining == 0})


if __name__ == "__main__":
    main()
