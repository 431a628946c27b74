"""Steps/s of a taskforge pick-place env (stage rewards + full randomisation) against the raw
Meta-World env, in the same run.

    python benchmarks/env_overhead.py [--steps 5000] [--repeats 3]

Both envs step the same pre-drawn random actions and reset (to a random ML1 train goal) when an
episode of 500 steps ends. Runs alternate raw/taskforge so machine noise hits both alike; the
median over repeats is reported. Goal: taskforge >= 0.9 x raw.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import taskforge  # noqa: E402
from benchmarks.common import print_table, versions, write_result  # noqa: E402
from taskforge.backends.metaworld import ml1_goals  # noqa: E402

TASK = Path(__file__).resolve().parents[1] / "tasks/metaworld/pick_place.yaml"
ENV_NAME = "pick-place-v3"


def raw_steps_per_second(actions: np.ndarray, seed: int) -> float:
    from metaworld.env_dict import ALL_V3_ENVIRONMENTS

    train, _ = ml1_goals(ENV_NAME, 0)
    rng = np.random.default_rng(seed)
    env = ALL_V3_ENVIRONMENTS[ENV_NAME]()
    env.set_task(train[0])
    env.reset()
    start = time.perf_counter()
    for action in actions:
        *_, truncated, _ = env.step(action)
        if truncated:
            env.set_task(train[int(rng.integers(len(train)))])
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def taskforge_steps_per_second(actions: np.ndarray, seed: int) -> float:
    env = taskforge.make(TASK, stage="place", seed=seed)
    env.reset()
    start = time.perf_counter()
    for action in actions:
        *_, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, 4)).astype(np.float32)
    ml1_goals(ENV_NAME, 0)  # build the goal sets once, outside the timed region
    raw, ours = [], []
    for r in range(args.repeats):
        raw.append(raw_steps_per_second(actions, seed=r))
        ours.append(taskforge_steps_per_second(actions, seed=r))
    raw_med, ours_med = statistics.median(raw), statistics.median(ours)
    ratio = ours_med / raw_med
    print_table(
        ["env", "median steps/s", "runs (steps/s)"],
        [["raw Meta-World pick-place-v3", raw_med, ", ".join(f"{x:.0f}" for x in raw)],
         ["taskforge pick-place (place stage, full randomisation)", ours_med, ", ".join(f"{x:.0f}" for x in ours)]],
    )
    print(f"ratio taskforge / raw = {ratio:.3f} (goal >= 0.9: {'met' if ratio >= 0.9 else 'NOT met'})")
    path = write_result(
        "env_overhead",
        {
            "steps": args.steps,
            "repeats": args.repeats,
            "raw_steps_per_s": raw,
            "taskforge_steps_per_s": ours,
            "raw_median": raw_med,
            "taskforge_median": ours_med,
            "ratio": ratio,
            "goal": ">= 0.9",
            "goal_met": ratio >= 0.9,
            "versions": versions("metaworld", "mujoco", "numpy", "gymnasium"),
        },
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
