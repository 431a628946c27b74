"""Is an MPC run's planner or its model what limits it? Two checks of one finished `algo: mpc` run:

1. The model: its one-step error on the object's motion, on the run's own buffer (its local
   `checkpoint.pt`), binned by how far the object really moved, next to predicting no motion.
   A model that has not learnt contact is no better than "no motion" where the object moved.
2. The planner: held-out success of the final model with the planner it trained with, and with
   a bigger one (200 candidates x 4 rounds x 15 steps, 20 elites: ~10x agents/mpc.yaml's search)
   on the same goals and seeds.

    python benchmarks/mpc_probe.py benchmarks/runs/model_based/mpc-push-seed0 [--trials 10] [--object 4:7]

`--object`: where the object's position sits in the observation (Meta-World: 4:7).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.rollouts import evaluate_rows  # noqa: E402
from taskforge.run import load_checkpoint, load_run  # noqa: E402

BIGGER = {"population": 200, "iterations": 4, "horizon": 15, "elites": 20}
BINS_MM = ((0, 2), (2, 5), (5, 10), (10, 1000))


def object_motion_errors(agent, obj: slice, sample: int = 5000) -> list[dict]:
    """Per bin of true object motion (mm): transitions in the buffer, the model's mean error and
    the error of predicting no motion, on up to `sample` transitions of the bin."""
    buffer = agent.buffer
    n = buffer.size
    obs, actions, next_obs = buffer.obs[:n], buffer.actions[:n], buffer.next_obs[:n]
    moved = (next_obs[:, obj] - obs[:, obj]).norm(dim=1) * 1000
    members = agent.mpc.ensemble_size
    rows = []
    for lo, hi in BINS_MM:
        idx = torch.nonzero((moved >= lo) & (moved < hi))[:, 0]
        pick = idx[:sample]
        with torch.no_grad():
            predicted, _ = agent.model.mean_prediction(obs[pick][None].expand(members, -1, -1), actions[pick][None].expand(members, -1, -1))
        error = (predicted.mean(0)[:, obj] - next_obs[pick, obj]).norm(dim=1) * 1000
        rows.append({"moved_mm": [lo, hi], "transitions": len(idx), "model_error_mm": error.mean().item() if len(pick) else None,
                     "no_motion_error_mm": moved[pick].mean().item() if len(pick) else None})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--object", default="4:7", help="the object's position in the observation, start:stop")
    args = parser.parse_args()
    run = load_run(args.run)
    agent = run.agent
    first, stop = (int(x) for x in args.object.split(":"))
    agent.load_state_dict(load_checkpoint(args.run / "checkpoint.pt")["agent"])  # the buffer: the final policy file has none
    motion = object_motion_errors(agent, slice(first, stop))
    print_table(["object moved (mm)", "transitions", "model error (mm)", "'no motion' error (mm)"],
                [[f"{r['moved_mm'][0]}-{r['moved_mm'][1]}", r["transitions"], r["model_error_mm"], r["no_motion_error_mm"]] for r in motion])
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
    payload = {"run": str(args.run), "step": agent.global_step, "stage": stages[-1], "trials": args.trials, "object_motion": motion, "planners": rows}
    print(f"wrote {write_result(f'mpc_probe_{args.run.name}', payload)}")


if __name__ == "__main__":
    main()
