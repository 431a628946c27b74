"""Does a push run's model know what a push does, and does its planner prefer one when shown it?

Meta-World's own push policy pushes the puck to `--episodes` held-out goals; then, for each
`algo: mpc` checkpoint given:

1. The model: on the scripted steps that moved the puck more than `--moved` metres, the members'
   mean prediction of its motion against the true one: the ratio of their lengths and the cosine
   of the angle between them (1 and 1: the model knows a push; ~0: it predicts the puck stays).
2. The planner's score: at every `--every`-th scripted step where the hand is within `--near`
   of the puck and the next `horizon` scripted actions bring the puck more than `--closer`
   nearer the goal, the run's own scorer (model, particles, terminal value) rates three action
   sequences: the scripted push, holding still (zero actions) and the run's own plan from that
   observation; which scores best, and the push's score minus holding still's.

Why: on push one seed took off and another sat with the hand on the puck, never pushing
(benchmarks/RESULTS.md, `mpc_data_probe.py`). A planner only chooses a push its model predicts;
a model only learns a push from data that holds pushes. This says which side of that loop a run
is on, from the run alone, in seconds.

    python benchmarks/mpc_push_probe.py benchmarks/runs/model_based/mpc-push-policy-value-long-seed0/final.pt
                                        benchmarks/runs/model_based/mpc-push-policy-value-long-seed1/checkpoint.pt
                                        [--episodes 4] [--every 10] [--moved 0.005] [--near 0.02]
                                        [--closer 0.02] [--repeats 8] [--out mpc_push_probe]

The run's task must append `object - tool, goal - object` (`observation.relative_positions`) and
observe its goal. Writes benchmarks/results/<out>.json.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from benchmarks.mpc_data_probe import object_run  # noqa: E402
from taskforge.agents import MPCAgent  # noqa: E402
from taskforge.demos import generate  # noqa: E402

OBJECT = slice(4, 7)  # Meta-World's puck position in the observation


@dataclass
class Episode:
    """One scripted episode: observations before and after each step, and the actions."""

    obs: np.ndarray
    actions: np.ndarray
    next_obs: np.ndarray


def scripted_episodes(task_file: str, stage: str, episodes: int) -> list[Episode]:
    """Meta-World's push policy on the first `episodes` held-out goals (goal k resets with seed k),
    recorded as demonstrations are (`taskforge.demos.generate`), failed episodes kept."""
    demos = generate(task_file, stage, episodes, split="test", keep_failed=True)
    ends = np.cumsum(demos.episode_lengths)[:-1]
    return [Episode(*parts) for parts in zip(*(np.split(x, ends) for x in (demos.observations, demos.actions, demos.next_observations())))]


def motion_agreement(agent: MPCAgent, data: list[Episode], moved: float) -> dict:
    """The model's predicted puck motion against the true one where the script moved it."""
    obs, actions, after = (torch.as_tensor(np.concatenate([getattr(e, f) for e in data])) for f in ("obs", "actions", "next_obs"))
    members = agent.mpc.ensemble_size
    with torch.no_grad():
        predicted, _ = agent.model.mean_prediction(obs[None].expand(members, -1, -1).to(agent.device),
                                                   actions[None].expand(members, -1, -1).to(agent.device))
    true = (after - obs)[:, OBJECT]
    guess = (predicted.mean(0).cpu() - obs)[:, OBJECT]
    rows = true.norm(dim=1) > moved
    ratio = guess[rows].norm(dim=1) / true[rows].norm(dim=1)
    cosine = torch.nn.functional.cosine_similarity(guess[rows], true[rows], dim=1)
    return {"steps": int(rows.sum()), "length_ratio_median": float(ratio.median()),
            "length_ratio_q25": float(ratio.quantile(0.25)), "length_ratio_q75": float(ratio.quantile(0.75)),
            "cosine_median": float(cosine.median())}


def push_states(data: list[Episode], horizon: int, every: int, near: float, closer: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """(observation, the next `horizon` scripted actions) where the hand is at the puck and those
    actions bring the puck more than `closer` nearer the goal (read off `goal - object`)."""
    states = []
    for e in data:
        for t in range(0, len(e.actions) - horizon, every):
            at_puck = np.linalg.norm(e.obs[t, -6:-3]) < near
            gain = np.linalg.norm(e.obs[t, -3:]) - np.linalg.norm(e.next_obs[t + horizon - 1, -3:])
            if at_puck and gain > closer:
                states.append((e.obs[t], e.actions[t:t + horizon]))
    return states


def planner_preference(agent: MPCAgent, states: list[tuple[np.ndarray, np.ndarray]], repeats: int) -> dict:
    """Which of (scripted push, holding still, the run's own plan) the run's scorer rates best,
    each score the mean of `repeats` draws of its particles."""
    best, margin = np.zeros(3, dtype=int), []
    for obs, script in states:
        with torch.no_grad():
            first, shifted = agent.act(obs[None])
            own = torch.cat([agent.to_unit(torch.as_tensor(first, device=agent.device)), shifted[0, :-1]])
            push = agent.to_unit(torch.as_tensor(script, device=agent.device))
            candidates = torch.stack([push, torch.zeros_like(push), own])[None]
            start = torch.as_tensor(obs[None], device=agent.device)
            mean = torch.stack([agent.score(start, candidates)[0] for _ in range(repeats)]).mean(0).cpu()
        best[int(mean.argmax())] += 1
        margin.append(float(mean[0] - mean[1]))
    return {"states": len(states), "best_push": int(best[0]), "best_hold": int(best[1]), "best_own_plan": int(best[2]),
            "push_minus_hold_median": float(np.median(margin)) if margin else None}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoints", nargs="+", type=Path)
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--every", type=int, default=10)
    parser.add_argument("--moved", type=float, default=0.005)
    parser.add_argument("--near", type=float, default=0.02)
    parser.add_argument("--closer", type=float, default=0.02)
    parser.add_argument("--repeats", type=int, default=8)
    parser.add_argument("--out", default="mpc_push_probe")
    args = parser.parse_args()

    results, data = [], None
    for path in args.checkpoints:
        run = object_run(path, "its model and planner are what this scores")
        _, task_file, stages = run.phases[-1]
        if data is None:  # one set of scripted pushes for every run: the same states scored
            data = scripted_episodes(task_file, stages[-1], args.episodes)
        agent = run.agent
        agent.generator.manual_seed(0)  # the particles' and the search's draws: same checkpoint, same table
        agent.plan_generator.manual_seed(0)
        states = push_states(data, agent.mpc.horizon, args.every, args.near, args.closer)
        results.append({"checkpoint": str(path), "step": agent.global_step,
                        "motion": motion_agreement(agent, data, args.moved),
                        "planner": planner_preference(agent, states, args.repeats)})

    print_table(["run", "step", "pushing steps", "predicted / true motion (q25-q75)", "cosine",
                 "push states", "best: push / hold / own plan", "push - hold"],
                [[Path(r["checkpoint"]).parent.name, f"{r['step']:,}", r["motion"]["steps"],
                  f"{r['motion']['length_ratio_median']:.2f} ({r['motion']['length_ratio_q25']:.2f}-{r['motion']['length_ratio_q75']:.2f})",
                  f"{r['motion']['cosine_median']:.2f}", r["planner"]["states"],
                  f"{r['planner']['best_push']} / {r['planner']['best_hold']} / {r['planner']['best_own_plan']}",
                  "-" if r["planner"]["push_minus_hold_median"] is None else f"{r['planner']['push_minus_hold_median']:.1f}"]
                 for r in results])
    path = write_result(args.out, {"runs": results, "episodes": args.episodes, "every": args.every, "moved": args.moved,
                                   "near": args.near, "closer": args.closer, "repeats": args.repeats})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
