"""What a memoryless search scores on ML1 reach with the goal hidden: a fixed raster sweep of the
goal box, the same for every goal, against Meta-World's success (within 5 cm at any step).

    python benchmarks/reach_sweep.py [--episodes 50] [--split test] [--limits 100 200 300 500]
    python benchmarks/reach_sweep.py --trial-episodes 10 --episode-steps 50 [--task T --stage S] [--height Z]

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

With `--trial-episodes K`, the ceiling of an RL² trial of K episodes of `--episode-steps` steps
(→ `reach_sweep_trials_<stage>_<episode steps>.json`): the sweep carried on from episode to episode (each episode
starts from the reset hand and heads for the first waypoint the last one did not reach) is what
a policy that remembers where it searched can do at best; success at episode k is the share of
goals found by then (a policy that remembers a find goes back in later episodes). A memoryless
policy repeats episode 1. `--height Z` sweeps one plane (both depths at height Z), for stages whose
goals lie on it (`goal.height`); `--task`/`--stage` pick the task and stage played.
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


def raster(height: float | None = None) -> list[np.ndarray]:
    """The sweep's waypoints, in order (a boustrophedon over x at each depth and height; only
    `height` if given)."""
    points, forward = [], True
    for y, heights in ((0.825, (0.26, 0.175, 0.09)), (0.875, (0.09, 0.175, 0.26))):
        for z in heights if height is None else (height,):
            xs = (-0.1, 0.1) if forward else (0.1, -0.1)
            points += [np.array([x, y, z]) for x in xs]
            forward = not forward
    return points


def first_success(env: TaskEnv, goal_index: int, seed: int, steps: int) -> int | None:
    """The step of the sweep's first success on one goal, None if it never succeeds."""
    env.reset(seed=seed, options={"goal_index": goal_index})
    waypoints, k = raster(), 0
    for t in range(1, steps + 1):
        k, (*_, info) = sweep_step(env, waypoints, k)
        if info["success"]:
            return t
    return None


def sweep_step(env: TaskEnv, waypoints: list[np.ndarray], k: int) -> tuple[int, tuple]:
    """One step of the sweep: waypoint `k` once the hand is there moves on to the next, and the
    hand is driven toward the current one at full speed. Returns the waypoint index and what
    `env.step` returned."""
    hand = np.asarray(env.unwrapped.backend.features()["tcp_pos"])
    if k < len(waypoints) - 1 and np.linalg.norm(waypoints[k] - hand) < REACHED:
        k += 1
    move = np.clip((waypoints[k] - hand) * 100.0, -1.0, 1.0)
    return k, env.step(np.append(move, -1.0).astype(np.float32))


def trial_first_find(env: TaskEnv, goal_index: int, seed: int, episodes: int, waypoints: list[np.ndarray]) -> int | None:
    """The episode (1-based) of a trial in which the carried-on sweep first succeeds on one goal,
    None if no episode does. The goal and physics draw are the trial's: one seed for all its
    episodes, as RL²'s trials keep the task."""
    k = 0
    for episode in range(1, episodes + 1):
        env.reset(seed=seed, options={"goal_index": goal_index})
        done = False
        while not done:
            k, (_, _, terminated, truncated, info) = sweep_step(env, waypoints, k)
            if info["success"]:
                return episode
            done = terminated or truncated
    return None


def trial_ceiling(args: argparse.Namespace) -> None:
    """`--trial-episodes`: success by episode k of the carried-on sweep (see the module doc)."""
    task_file = Path(args.task)
    task = load_task(task_file)
    env = TaskEnv(task.model_copy(update={"max_episode_steps": args.episode_steps}), task_file, split=args.split, stage=args.stage)
    goals = env.unwrapped.backend.num_goals(args.split)
    finds = [trial_first_find(env, n % goals, args.seed + n, args.trial_episodes, raster(args.height)) for n in range(args.episodes)]
    env.close()
    by_episode = [float(np.mean([f is not None and f <= k for f in finds])) for k in range(1, args.trial_episodes + 1)]
    print_table(["episode of the trial", "carried-on sweep: found by then", "memoryless sweep"],
                [[k, f"{rate:.2f}", f"{by_episode[0]:.2f}"] for k, rate in enumerate(by_episode, 1)])
    name = f"reach_sweep_trials_{args.stage or task.stages[0].name}_{args.episode_steps}"  # one file per setting compared
    path = write_result(name, {
        "task": str(task_file.resolve().relative_to(ROOT)), "stage": args.stage, "split": args.split, "episodes": args.episodes,
        "seed": args.seed, "episode_steps": args.episode_steps, "trial_episodes": args.trial_episodes, "height": args.height,
        "found_by_episode": by_episode, "first_find_episode": finds})
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--split", choices=["train", "test"], default="test")
    parser.add_argument("--limits", type=int, nargs="+", default=[100, 200, 300, 500])
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--trial-episodes", type=int, help="the ceiling of a trial of this many episodes (see the module doc)")
    parser.add_argument("--episode-steps", type=int, default=50, help="with --trial-episodes: steps per episode")
    parser.add_argument("--task", default=str(TASK), help="with --trial-episodes: the task file")
    parser.add_argument("--stage", help="with --trial-episodes: the stage played (default the task's first)")
    parser.add_argument("--height", type=float, help="with --trial-episodes: sweep only this height (goals on one plane)")
    args = parser.parse_args()
    if args.trial_episodes:
        trial_ceiling(args)
        return
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
