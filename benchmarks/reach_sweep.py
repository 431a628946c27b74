"""What a memoryless search scores on ML1 reach with the goal hidden: a fixed raster sweep of the
goal box, the same for every goal, against Meta-World's success (within 5 cm at any step).

    python benchmarks/reach_sweep.py [--episodes 50] [--split test] [--limits 100 200 300 500]

Why: RL² and the memoryless PPO baseline both score ~0.25-0.30 on ML1 reach's held-out goals
(benchmarks/RESULTS.md, RL² on ML1). A policy that cannot remember can still search: it can pass
near every point of the goal box once per episode. This is the floor an adapting policy's first
episode should reach, and it tells how much room the episode length leaves for adaptation (a
sweep that finds every goal in episode 1 leaves none). The task is tasks/metaworld/reach_meta.yaml
(its randomisation, goals and success), run for up to max(--limits) steps; a cell is the share of
episodes, one per goal of --split, whose first success came within that many steps.

The sweep: two depths of the box (y 0.825 and 0.875 m), three heights each (z 0.09, 0.175,
0.26 m), a pass along x from -0.1 to 0.1 m on each; the lines are close enough that every point of
ML1 reach's goal box lies within 5 cm of one. The hand is driven toward the next waypoint at full
speed (the action is the offset in cm, clipped to 1).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.envs import TaskEnv, load_task  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TASK = ROOT / "tasks/metaworld/reach_meta.yaml"
REACHED = 0.01  # m: close enough to a waypoint to head for the next


def raster() -> list[np.ndarray]:
    """The sweep's waypoints, in order (a boustrophedon over x at each depth and height)."""
    points, forward = [], True
    for y, heights in ((0.825, (0.26, 0.175, 0.09)), (0.875, (0.09, 0.175, 0.26))):
        for z in heights:
            xs = (-0.1, 0.1) if forward else (0.1, -0.1)
            points += [np.array([x, y, z]) for x in xs]
            forward = not forward
    return points


def first_success(env: TaskEnv, goal_index: int, seed: int, steps: int) -> int | None:
    """The step of the sweep's first success on one goal, None if it never succeeds."""
    env.reset(seed=seed, options={"goal_index": goal_index})
    waypoints, k = raster(), 0
    for t in range(1, steps + 1):
        hand = np.asarray(env.unwrapped.backend.features()["tcp_pos"])
        if k < len(waypoints) - 1 and np.linalg.norm(waypoints[k] - hand) < REACHED:
            k += 1
        move = np.clip((waypoints[k] - hand) * 100.0, -1.0, 1.0)
        *_, info = env.step(np.append(move, -1.0).astype(np.float32))
        if info["success"]:
            return t
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--split", choices=["train", "test"], default="test")
    parser.add_argument("--limits", type=int, nargs="+", default=[100, 200, 300, 500])
    parser.add_argument("--seed", type=int, default=100)
    args = parser.parse_args()
    task = load_task(TASK)
    longest = max(args.limits)
    env = TaskEnv(task.model_copy(update={"max_episode_steps": longest}), TASK, split=args.split)
    goals = env.unwrapped.backend.num_goals(args.split)
    hits = [first_success(env, n % goals, args.seed + n, longest) for n in range(args.episodes)]
    env.close()
    rates = {limit: float(np.mean([h is not None and h <= limit for h in hits])) for limit in args.limits}
    print_table(["episode length (steps)", "sweep success"], [[limit, f"{rate:.2f}"] for limit, rate in rates.items()])
    path = write_result("reach_sweep", {"task": str(TASK.relative_to(ROOT)), "split": args.split, "episodes": args.episodes,
                                        "seed": args.seed, "success_within": rates, "first_success_step": hits})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
