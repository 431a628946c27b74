"""Does an RL² policy use its reward input? Meta-test one checkpoint twice on the same trials:
as trained, and with the previous-reward input the policy reads held at 0.

    python benchmarks/rl2_reward_ablation.py benchmarks/runs/rl2/rl2-reach-seed0 [--trials 50] [--sampled]

RL² can only find a hidden goal through the rewards it has seen, so an agent that adapts must
lose success when that input is blanked (most in the trial's later episodes). No change means
it acts like a memoryless policy with a GRU attached. The ablation patches the trial wrapper's
input assembly (`RL2Trial._observe`) for the second evaluation only; the environment, its
rewards, the trials (goals, seeds) and the actions' mode are otherwise identical. `--sampled` samples
the actions instead of taking the mean: a policy whose search lives in its sampling noise (the
Meta-World+ preset's) is only measured that way. Writes
benchmarks/results/rl2_reward_ablation_<run>[_sampled].json.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.agents.rl2 import RL2Trial  # noqa: E402
from taskforge.evaluation.report import evaluate_run  # noqa: E402


@contextmanager
def reward_input_blanked() -> Iterator[None]:
    """Every `RL2Trial` built inside this block shows the policy a previous reward of 0."""
    original = RL2Trial._observe

    def observe(self: RL2Trial, obs, action, reward, start):
        return original(self, obs, action, 0.0, start)

    RL2Trial._observe = observe
    try:
        yield
    finally:
        RL2Trial._observe = original


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="an RL² run directory or checkpoint")
    parser.add_argument("--trials", type=int, default=50, help="meta-test trials (held-out goals 0..trials-1)")
    parser.add_argument("--split", default="test", choices=["train", "test"])
    parser.add_argument("--sampled", action="store_true", help="sample actions instead of the mean")
    args = parser.parse_args()

    rows, results = [], {}
    for name, ablation in (("as trained", nullcontext()), ("reward input = 0", reward_input_blanked())):
        with ablation:
            report = evaluate_run(args.run, split=args.split, trials=args.trials, deterministic=not args.sampled)
        row = report["rows"][0]
        per_episode = [e["success_rate"] for e in row["per_episode"]]
        results[name] = {"success_rate": row["success_rate"], "per_episode": per_episode, "step": report["step"]}
        rows.append([name, f"{row['success_rate']:.3f}", " ".join(f"{p:.2f}" for p in per_episode)])
    print_table(["reward input", f"{args.split} success", "per episode of the trial"], rows)
    stem = Path(args.run).name.replace(".pt", "")
    path = write_result(f"rl2_reward_ablation_{stem}" + ("_sampled" if args.sampled else ""),
                        {"run": str(args.run), "split": args.split, "trials": args.trials,
                         "actions": "sampled" if args.sampled else "mean", "results": results})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
