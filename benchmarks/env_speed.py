"""Env steps/s on pick-place-v3: Meta-World's own step, taskforge's env, EnvPool's C++
Meta-World and bare `mj_step` x frame_skip, single-process and vectorised over every core, in
one run.

    python benchmarks/env_speed.py [--steps 3000] [--repeats 3] [--envs-per-core 4]

Rows:
- Meta-World's own `env.step` (its reward evaluation included), ML1 train goals;
- taskforge's env: tasks/metaworld/pick_place.yaml, `place` stage, full randomisation, relative
  positions; it skips Meta-World's reward (the stage does not read it) and uses the cheaper
  observation (taskforge/backends/metaworld_step.py);
- EnvPool's C++ Meta-World (`MetaWorld/PickPlace-v3`), the fastest implementation available;
  optional (`pip install -c constraints.txt envpool`): its row says so when it is missing;
- `mujoco.mj_step(model, data, frame_skip)` on the same model with random controls: physics
  alone, the ceiling.
Single-process rows step one env (EnvPool: one env, one thread). Vectorised rows run
`--envs-per-core` envs per core: the Python envs in taskforge's sharded vector env (one worker
process per core), EnvPool with one thread per core. Every row steps the same pre-drawn random
actions; runs alternate row by row so machine noise hits all alike; medians are reported. Goal
(issue 19): taskforge's env >= 2.5 x Meta-World's own step, single process.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, versions, write_result  # noqa: E402
from benchmarks.pick_place_envs import ENV_NAME, MetaWorldEnv, taskforge_env  # noqa: E402
from taskforge.agents.sharded import ShardedVectorEnv  # noqa: E402
from taskforge.backends.metaworld import ml1_goals  # noqa: E402

ROWS: dict[str, Callable[[], gymnasium.Env]] = {
    "Meta-World's own step": MetaWorldEnv,
    "taskforge env (place, full randomisation)": taskforge_env,
    "mj_step x frame_skip (physics only)": lambda: MetaWorldEnv(physics_only=True),
}
ENVPOOL = "EnvPool C++ Meta-World"


def single(make: Callable[[], gymnasium.Env], actions: np.ndarray) -> float:
    env = make()
    env.reset(seed=0)
    start = time.perf_counter()
    for action in actions:
        *_, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return len(actions) / (time.perf_counter() - start)


def vectorised(make: Callable[[], gymnasium.Env], actions: np.ndarray, cores: int, per_core: int) -> float:
    n = cores * per_core
    envs = ShardedVectorEnv([make] * n, num_shards=cores)
    envs.reset(seed=0)
    batches = actions[: len(actions) // n * n].reshape(-1, n, actions.shape[1])
    start = time.perf_counter()
    for batch in batches:
        envs.step(batch)  # finished episodes reset inside the step (taskforge's envs end at 500 steps)
    rate = batches.size // actions.shape[1] / (time.perf_counter() - start)
    envs.close()
    return rate


def envpool_rate(actions: np.ndarray, num_envs: int, threads: int) -> float | None:
    try:
        import envpool
    except ImportError:
        return None
    envs = envpool.make("MetaWorld/PickPlace-v3", env_type="gymnasium", num_envs=num_envs, num_threads=threads, seed=0)
    envs.reset()
    batches = actions[: len(actions) // num_envs * num_envs].reshape(-1, num_envs, actions.shape[1])
    start = time.perf_counter()
    for batch in batches:
        envs.step(batch)
    return batches.size // actions.shape[1] / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000, help="env steps per row and run (single-process; x cores vectorised)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--envs-per-core", type=int, default=4)
    args = parser.parse_args()
    cores = os.cpu_count() or 1

    ml1_goals(ENV_NAME, 0)  # build the goal sets once, outside the timed region
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (args.steps * cores, 4)).astype(np.float32)
    runs: dict[str, dict[str, list[float]]] = {name: {"single": [], "vectorised": []} for name in [*ROWS, ENVPOOL]}
    for _ in range(args.repeats):
        for name, make in ROWS.items():
            runs[name]["single"].append(single(make, actions[: args.steps]))
            runs[name]["vectorised"].append(vectorised(make, actions, cores, args.envs_per_core))
        one = envpool_rate(actions[: args.steps], num_envs=1, threads=1)
        if one is not None:
            runs[ENVPOOL]["single"].append(one)
            runs[ENVPOOL]["vectorised"].append(envpool_rate(actions, num_envs=cores * args.envs_per_core, threads=cores))

    medians = {name: {k: statistics.median(v) if v else None for k, v in r.items()} for name, r in runs.items()}
    own = medians["Meta-World's own step"]
    rows = []
    for name, m in medians.items():
        if m["single"] is None:
            rows.append([name, "not installed (pip install -c constraints.txt envpool)", "", "", ""])
            continue
        rows.append([name, m["single"], m["vectorised"], f"{m['single'] / own['single']:.2f}", f"{m['vectorised'] / own['vectorised']:.2f}"])
    print_table(["env", "steps/s, 1 process", f"steps/s, {cores} cores", "x own step (1 proc)", f"x own step ({cores} cores)"], rows)
    ratio = medians["taskforge env (place, full randomisation)"]["single"] / own["single"]
    print(f"taskforge env / Meta-World's own step, single process: {ratio:.2f} (goal >= 2.5: {'met' if ratio >= 2.5 else 'NOT met'})")
    path = write_result("env_speed", {
        "steps": args.steps, "repeats": args.repeats, "cores": cores, "envs_per_core": args.envs_per_core,
        "runs": runs, "medians": medians, "taskforge_over_metaworld_single": ratio, "goal": ">= 2.5", "goal_met": ratio >= 2.5,
        "versions": versions("metaworld", "mujoco", "numpy", "gymnasium", *(["envpool"] if runs[ENVPOOL]["single"] else [])),
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
