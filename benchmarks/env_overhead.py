"""Steps/s of a taskforge pick-place env (stage rewards + full randomisation) against the raw
Meta-World env, in the same run.

    python benchmarks/env_overhead.py [--steps 5000] [--repeats 3]

Both envs step the same pre-drawn random actions and, when an episode of 500 steps ends, reset to
the same sequence of ML1 train goals, so both simulate the same scenes (taskforge's physics
randomisation, noise and latency still change the trajectories: that cost is part of what is
measured). Runs alternate raw/taskforge so machine noise hits both alike; the
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
from taskforge.envs import TaskEnv  # noqa: E402
from taskforge.spec import RandomizationSpec  # noqa: E402

TASK = Path(__file__).resolve().parents[1] / "tasks/metaworld/pick_place.yaml"
ENV_NAME = "pick-place-v3"


def goal_sequence(seed: int):
    """The ML1 train-goal index of each successive episode, shared by both envs."""
    rng = np.random.default_rng(seed)
    while True:
        yield int(rng.integers(50))


def raw_steps_per_second(actions: np.ndarray, seed: int) -> float:
    from metaworld.env_dict import ALL_V3_ENVIRONMENTS

    train, _ = ml1_goals(ENV_NAME, 0)
    goals = goal_sequence(seed)
    env = ALL_V3_ENVIRONMENTS[ENV_NAME]()
    env.set_task(train[next(goals)])
    env.reset()
    start = time.perf_counter()
    for action in actions:
        *_, truncated, _ = env.step(action)
        if truncated:
            env.set_task(train[next(goals)])
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def taskforge_steps_per_second(actions: np.ndarray, seed: int, randomize: bool = True) -> float:
    goals = goal_sequence(seed)
    if randomize:
        env = taskforge.make(TASK, stage="place", seed=seed)
    else:
        spec = taskforge.load_task(TASK).model_copy(update={"randomization": RandomizationSpec()})
        env = TaskEnv(spec, TASK, stage="place", seed=seed)
    env.reset(options={"goal_index": next(goals)})
    start = time.perf_counter()
    for action in actions:
        *_, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset(options={"goal_index": next(goals)})
    return len(actions) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, 4)).astype(np.float32)
    ml1_goals(ENV_NAME, 0)  # build the goal sets once, outside the timed region
    raw, ours, plain = [], [], []
    for r in range(args.repeats):
        raw.append(raw_steps_per_second(actions, seed=r))
        ours.append(taskforge_steps_per_second(actions, seed=r))
        plain.append(taskforge_steps_per_second(actions, seed=r, randomize=False))
    raw_med, ours_med, plain_med = statistics.median(raw), statistics.median(ours), statistics.median(plain)
    ratio = ours_med / raw_med
    print_table(
        ["env", "median steps/s", "runs (steps/s)"],
        [["raw Meta-World pick-place-v3", raw_med, ", ".join(f"{x:.0f}" for x in raw)],
         ["taskforge pick-place (place stage, full randomisation)", ours_med, ", ".join(f"{x:.0f}" for x in ours)],
         ["taskforge, randomisation off (same trajectories as raw)", plain_med, ", ".join(f"{x:.0f}" for x in plain)]],
    )
    print(f"ratio taskforge / raw = {ratio:.3f} (goal >= 0.9: {'met' if ratio >= 0.9 else 'NOT met'}); "
          f"without randomisation {plain_med / raw_med:.3f}")
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
            "taskforge_no_randomisation_steps_per_s": plain,
            "ratio_no_randomisation": plain_med / raw_med,
            "goal": ">= 0.9",
            "goal_met": ratio >= 0.9,
            "versions": versions("metaworld", "mujoco", "numpy", "gymnasium"),
        },
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
