"""Is an MPC run's planner or its model what limits it? Evaluate one finished `algo: mpc` run's
final model on held-out goals twice: with the planner it trained with, and with a bigger one
(default 200 candidates x 4 rounds x 15 steps, 20 elites: ~10x the search of agents/mpc.yaml).

    python benchmarks/mpc_planner_size.py benchmarks/runs/model_based/mpc-push-seed0 [--trials 10]

If the bigger search succeeds where the shipped one does not, the model knows the way and the
search misses it; if neither does, the model (or what a short horizon can see) is the limit.
Both evaluations play the same goals and seeds with the model's weights unchanged.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.rollouts import evaluate_rows  # noqa: E402
from taskforge.run import load_run  # noqa: E402

BIGGER = {"population": 200, "iterations": 4, "horizon": 15, "elites": 20}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--trials", type=int, default=10)
    args = parser.parse_args()
    run = load_run(args.run)
    agent = run.agent
    task, task_file, stages = run.phases[-1]
    rows = []
    for label, change in (("as trained", {}), ("bigger search", BIGGER)):
        agent.mpc = agent.spec.planning.model_copy(update=change)
        start = time.perf_counter()
        (result,) = evaluate_rows(agent, task, task_file, [(stages[-1], None)], "test", args.trials, 1, seed=0, stop_on_success=True)
        rows.append({"planner": label, **agent.mpc.model_dump(include={"population", "iterations", "horizon", "elites"}),
                     "success_rate": result.as_dict()["success_rate"], "seconds": time.perf_counter() - start})
    print_table(["planner", "population x rounds x horizon", "held-out success", "s"],
                [[r["planner"], f"{r['population']} x {r['iterations']} x {r['horizon']}", f"{r['success_rate']:.2f}", r["seconds"]] for r in rows])
    print(f"wrote {write_result(f'mpc_planner_size_{args.run.name}', {'run': str(args.run), 'step': agent.global_step, 'stage': stages[-1], 'trials': args.trials, 'rows': rows})}")


if __name__ == "__main__":
    main()
