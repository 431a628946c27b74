"""Scripted-demo success and episode length per stage on held-out goals, full randomisation.

    python benchmarks/demos.py [--episodes 200] [--tasks tasks/xarm7/pick_place.yaml ...]

Each stage of each task runs `--episodes` scripted episodes (the waypoint planner; the
simulator's own policy on Meta-World's last stage) on the *test* split with the task's full
randomisation. For xArm7 the test split is enlarged to `--episodes` goals, so every episode has
its own held-out goal; Meta-World has 50 held-out ML1 goals, each visited several times under
different randomisation draws. Length = control steps until the stage's success first held.
Goal: >= 95 % on xArm7 pick-place.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.demos import record, scripted_policy  # noqa: E402
from taskforge.envs import TaskEnv, load_task  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_TASKS = ["tasks/xarm7/pick_place.yaml", "tasks/metaworld/pick_place.yaml"]


def held_out_task(path: Path, episodes: int):
    task = load_task(path)
    if task.backend.type == "xarm7":
        test = task.goals.test.model_copy(update={"count": episodes})
        task = task.model_copy(update={"goals": task.goals.model_copy(update={"test": test})})
    return task


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--tasks", nargs="+", default=DEFAULT_TASKS)
    parser.add_argument("--seed", type=int, default=1000)
    args = parser.parse_args()
    rows, results = [], {}
    for rel in args.tasks:
        path = ROOT / rel
        task = held_out_task(path, args.episodes)
        for stage in task.stage_names:
            env = TaskEnv(task, path, stage=stage, split="test")
            start = time.perf_counter()
            demos = record(env, scripted_policy(env, stage), args.episodes, seed=args.seed, keep_failed=True, progress=True)
            wall = time.perf_counter() - start
            ends = np.cumsum(demos.episode_lengths)
            firsts = [int(np.argmax(demos.successes[e - n:e])) + 1
                      for e, n, ok in zip(ends, demos.episode_lengths, demos.episode_success) if ok]
            rate = float(np.mean(demos.episode_success))
            results[f"{rel}:{stage}"] = {"task": rel, "stage": stage, "episodes": args.episodes, "success_rate": rate,
                                         "mean_steps_to_success": float(np.mean(firsts)) if firsts else None,
                                         "policy": scripted_policy(env, stage).name, "wall_s": wall}
            rows.append([rel, stage, f"{rate:.1%}", f"{np.mean(firsts):.0f}" if firsts else "-", results[f"{rel}:{stage}"]["policy"]])
            env.close()
    print_table(["task", "stage", "success", "steps to success", "policy"], rows)
    write_result("demos", {"episodes": args.episodes, "split": "test", "seed": args.seed, "results": results,
                           "goal": ">= 95% on xArm7 pick-place (place stage)"})


if __name__ == "__main__":
    main()
