"""Meta-World pick-place without demos: the 4-stage curriculum vs flat training on the `place`
stage, several seeds, success on held-out (ML1 test) goals vs env steps.

    python benchmarks/pick_place_curriculum.py [--seeds 0 1 2] [--steps 2000000] [--chunk-steps 200000]

The full budget (2 variants x 3 seeds x 2M steps) takes many hours on 2 cores, so the script
works in chunks: each call advances every run by at most `--chunk-steps` (resuming from its
checkpoint) and rewrites the result table from what exists so far. Run it again to continue.
Both variants evaluate the `place` stage on 20 held-out goals every 100k steps (the curricula's
`evaluation` settings), so their curves measure the same thing.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import advance_run, print_table, write_result  # noqa: E402
from taskforge.training.checkpoint import load_checkpoint  # noqa: E402
from taskforge.training.metrics import read_jsonl  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = {"curriculum": ROOT / "curricula/pick_place.yaml", "flat": ROOT / "benchmarks/configs/pick_place_flat.yaml"}
RUNS = ROOT / "benchmarks/runs/pick_place"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=2_000_000)
    parser.add_argument("--chunk-steps", type=int, default=200_000)
    parser.add_argument("--report-only", action="store_true", help="summarise the runs so far, train nothing")
    args = parser.parse_args()

    runs = {}
    for seed in args.seeds:
        for variant in VARIANTS:
            run_dir = RUNS / f"{variant}-seed{seed}"
            if args.report_only:
                if not (run_dir / "checkpoint.pt").exists():
                    continue
                step = load_checkpoint(run_dir / "checkpoint.pt")["agent"]["global_step"]
            else:
                start = time.perf_counter()
                step = advance_run(VARIANTS[variant], run_dir, seed, args.steps, args.chunk_steps)
                print(f"{variant} seed {seed}: {step:,} / {args.steps:,} steps ({time.perf_counter() - start:.0f} s this call)", flush=True)
            metrics = read_jsonl(run_dir / "metrics.jsonl")
            runs[f"{variant}-seed{seed}"] = {
                "variant": variant, "seed": seed, "steps_done": step,
                "eval_place_success": [(m["step"], m["eval_success_rate"]) for m in metrics if "eval_success_rate" in m],
                "promotions": [(e["step"], e["to_stage"]) for e in read_jsonl(run_dir / "events.jsonl")],
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
    write_result("pick_place_curriculum", {"seeds": args.seeds, "steps": args.steps, "runs": runs, "remaining_steps": remaining,
                                           "complete": remaining == 0})


if __name__ == "__main__":
    main()
