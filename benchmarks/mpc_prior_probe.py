"""Does an MPC run's planner follow its demos' prior, and how wide may its search be? On one
`algo: mpc` checkpoint with `mpc.prior_trajectories` (e.g. the warm start's, before any planned
step), held-out success on the same goals and seeds of:

1. the prior alone (the cloned policy's action, no planning): what the demos taught;
2. the planner without the prior (the model and terminal value only, the search from the
   previous plan): what the model alone makes of the task;
3. the planner with the prior at each `--init-std` (its search starts from the prior's rollout;
   `init_std` is how far it may stray).

    python benchmarks/mpc_prior_probe.py benchmarks/runs/model_based/mpc-pick-place-demos-prior-seed0/checkpoint.pt
                                         [--trials 8] [--init-std 0.1 0.25 0.5] [--seed 1000]
                                         [--players prior unguided guided] [--out mpc_prior_probe]

`--players` picks the rows (the planner without the prior costs the most: it rarely ends an
episode early); `--seed 10000` with `--trials 50` gives a seed-0 run's own evaluation goals (the
trainer evaluates at the run's seed + 10,000), so a row lines up with the run's curve, and
`guided` at the run's own `init_std` is the run's planner. Each row names the goals it missed
(indices into the test split), so whether the planner fails where its prior fails is read goal
by goal.

Writes benchmarks/results/<out>.json.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.agents import MPCAgent  # noqa: E402
from taskforge.rollouts import evaluate_rows  # noqa: E402
from taskforge.run import load_run  # noqa: E402


class PriorOnly:
    """The agent's cloned policy acting alone: `act` as `evaluate_rows` calls it."""

    def __init__(self, agent: MPCAgent):
        self.agent = agent

    def __getattr__(self, name: str):
        return getattr(self.agent, name)

    def act(self, obs: np.ndarray, state=None, episode_start=None, deterministic: bool = True):
        return self.agent.prior_act(obs), state


PLAYERS = ("prior", "unguided", "guided")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--trials", type=int, default=8, help="held-out goals (test split), one episode each")
    parser.add_argument("--init-std", type=float, nargs="+", default=[0.1, 0.25, 0.5])
    parser.add_argument("--seed", type=int, default=1000, help="seed of the first trial's reset (one per trial after it)")
    parser.add_argument("--players", nargs="+", choices=PLAYERS, default=list(PLAYERS), help="which rows to measure")
    parser.add_argument("--out", default="mpc_prior_probe", help="results file name, without .json")
    args = parser.parse_args()
    run = load_run(args.checkpoint)
    agent = run.agent
    if not isinstance(agent, MPCAgent) or agent.prior is None:
        sys.exit(f"error: {args.checkpoint}: not an algo: mpc run with mpc.prior_trajectories")
    task, task_file, stages = run.phases[-1]
    stage = run.config["curriculum"]["evaluation"].get("stage") or stages[-1]
    prior, spec = agent.prior, agent.mpc

    def success(player) -> dict:
        start = time.perf_counter()
        row = evaluate_rows(player, task, task_file, [(stage, None)], "test", args.trials, seed=args.seed, stop_on_success=True)[0]
        return {"success": row.success_rate, "seconds": time.perf_counter() - start,
                "missed_goals": row.missed_goals}

    rows = {}
    if "prior" in args.players:
        rows["prior alone"] = success(PriorOnly(agent))
    if "unguided" in args.players:
        agent.prior = None
        rows[f"planner without the prior (init_std {spec.init_std:g})"] = success(agent)
        agent.prior = prior
    for std in args.init_std if "guided" in args.players else []:
        agent.mpc = spec.model_copy(update={"init_std": std})
        rows[f"planner from the prior, init_std {std:g}"] = success(agent)
    print(f"{args.checkpoint} at step {agent.global_step:,}: {stage} on {args.trials} held-out goals")
    print_table(["player", "success", "seconds", "missed goals"],
                [[k, f"{v['success']:.2f}", v["seconds"], ", ".join(map(str, v["missed_goals"])) or "-"] for k, v in rows.items()])
    payload = {"checkpoint": str(args.checkpoint), "step": agent.global_step, "stage": stage, "trials": args.trials,
               "seed": args.seed, "rows": rows}
    print(f"wrote {write_result(args.out, payload)}")


if __name__ == "__main__":
    main()
