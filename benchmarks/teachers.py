"""Meta-World's scripted policies as MT10's teachers: as Meta-World ships them vs as taskforge
feeds them (`demos.policies.AIM_FINGERTIPS`, `READ_AS_HELD`), on their own path and off it.

    python benchmarks/teachers.py [--tasks reach-v3 push-v3 pick-place-v3 peg-insert-side-v3]
                                  [--episodes 30] [--noise 0 0.3 0.6] [--split train]

Each cell is the success rate of `--episodes` episodes of tasks/metaworld/mt10.yaml (its full
randomisation), one per goal of `--split`, with Gaussian noise of std `--noise` added to every
action. Why the noise: DAgger asks the teacher for labels in the student's states, which are off
the teacher's own path; a teacher that cannot finish the task from there gives labels a student
cannot succeed with. Noise puts the teacher in such states (an early grasp, an off-centre one).
"Shipped" reads Meta-World's observation as it is; "taskforge" through `MetaWorldPolicy`.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.demos import MetaWorldPolicy  # noqa: E402
from taskforge.envs import TaskEnv, load_task  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MT10 = ROOT / "tasks/metaworld/mt10.yaml"
MAX_STEPS = 500


def success_rate(env: TaskEnv, name: str, corrected: bool, noise: float, episodes: int, split: str, seed: int) -> float:
    """Episodes of one MT10 task, one per goal, each ended at its first success."""
    from metaworld.policies import ENV_POLICY_MAP

    backend = env.unwrapped.backend
    shipped = ENV_POLICY_MAP[name]()
    taskforge = MetaWorldPolicy([name])
    rng = np.random.default_rng(seed)
    wins = 0
    for n in range(episodes):
        env.reset(seed=seed + n, options={"task": name, "goal_index": n % backend.num_goals(split)})
        for _ in range(MAX_STEPS):
            if corrected:
                action = taskforge(env.unwrapped)
            else:
                with warnings.catch_warnings():  # `move()` warns whenever its gain saturates the action
                    warnings.simplefilter("ignore", UserWarning)
                    action = shipped.get_action(backend.native_observation())
            action = np.clip(action, -1.0, 1.0) + noise * rng.standard_normal(4)
            *_, terminated, truncated, info = env.step(action.astype(np.float32))
            if info["success"]:
                wins += 1
                break
            if terminated or truncated:
                break
    return wins / episodes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=["reach-v3", "push-v3", "pick-place-v3", "peg-insert-side-v3"])
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.3, 0.6])
    parser.add_argument("--split", choices=["train", "test"], default="train")
    parser.add_argument("--seed", type=int, default=100)
    args = parser.parse_args()
    task = load_task(MT10)
    env = TaskEnv(task, MT10, stage=task.stage_names[-1], split=args.split)
    rows, cells = [], []
    for name in args.tasks:
        for noise in args.noise:
            rates = {version: success_rate(env, name, version == "taskforge", noise, args.episodes, args.split, args.seed)
                     for version in ("shipped", "taskforge")}
            cells.append({"task": name, "noise_std": noise, **rates})
            rows.append([name, noise, f"{rates['shipped']:.2f}", f"{rates['taskforge']:.2f}"])
            print(f"{name} noise {noise}: shipped {rates['shipped']:.2f}, taskforge {rates['taskforge']:.2f}", flush=True)
    env.close()
    print_table(["task", "action noise std", "shipped", "taskforge"], rows)
    path = write_result("teachers", {"episodes": args.episodes, "split": args.split, "seed": args.seed, "cells": cells})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
