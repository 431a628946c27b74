"""What a memoryless push scores on ML1 push with the goal hidden, and what a trial that remembers
its misses can reach: the push-side twin of benchmarks/reach_sweep.py.

    python benchmarks/push_sweep.py [--trials 50] [--split test] [--episode-steps 150] [--headings 0 25 -25 50 -50]

Why: rl2-push-zone-find (benchmarks/configs/push_meta_zone_find.yaml) pays only when the puck
enters a ball around the hidden goal, so a policy must search by pushing. A scripted push sets the
two references its adaptation curve is read against, on the same task, stage (`push`, Meta-World's
5 cm), held-out goals and puck draws as the meta-test:
- the memoryless push: the first heading in every episode (a policy that cannot remember repeats
  its first episode; its curve is flat at this level);
- the carried-on fan: episode k of a trial pushes along the k-th heading, so success at episode k
  is the share of goals found by then. This is what a policy that remembers which headings missed
  (and goes back to a heading that hit) can do at best with this fan.

The push: the demos' push planner (taskforge.demos.policies.WaypointPlanner), aimed at a point
35 cm from the puck's start along a heading instead of at the goal, until the episode ends
(success ends it). A heading is in degrees from +y (away from the robot, where ML1 push's goals
lie), positive toward +x. 2-core AMD EPYC: ~10 s for 50 trials.

These are straight pushes, so the memoryless level here is a floor, not the best a memoryless
search can do: ML1 push's goals all lie within 5 cm of the line y = 0.85 m, and a push that
sweeps the puck along it (what the memoryless PPO baseline learnt, ppo-push-zone-find) finds
0.96 in one 150-step episode (benchmarks/RESULTS.md, "ML1 push: the find-once shape").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, write_result  # noqa: E402
from taskforge.demos.policies import PlannerConfig, WaypointPlanner  # noqa: E402
from taskforge.envs import TaskEnv, load_task  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TASK = ROOT / "benchmarks/configs/push_meta_zone_find.yaml"
STAGE = "push"
REACH = 0.35  # m: the aim point lies this far from the puck's start along the heading (past every goal)
PLANNER = PlannerConfig(push_lead=0.1)
"""The demos' push planner at full speed: it slows down near its target so as not to overshoot,
but here the target lies past every goal. With its default 2 cm lead a push aimed straight at
the hidden goal found 0.67 of 30 held-out goals in 150 steps, with 5 cm 0.97, with 10 cm 1.00."""


class _Aimed:
    """The env as the push planner sees it: every feature as is, but the goal moved to the aim
    point (the planner pushes toward `goal_pos`; the real goal stays hidden from it)."""

    def __init__(self, env: TaskEnv, aim: np.ndarray):
        self.env, self.aim = env, aim

    def features(self) -> dict:
        return {**self.env.features(), "goal_pos": self.aim}


def pushed_to_goal(env: TaskEnv, goal_index: int, seed: int, heading: float) -> bool:
    """Whether one episode's push along `heading` brings the puck within the stage's success
    distance of goal `goal_index`. `seed` draws the puck's start (the trial's: every episode of a
    trial resets with the same seed, as RL²'s trials keep the task). The push is the demos'
    planner (`WaypointPlanner("push")`, at `PLANNER`'s speed) aimed at
    a point past the goal region: it goes round behind the puck and keeps it on the line."""
    env.reset(seed=seed, options={"goal_index": goal_index})
    puck_start = np.asarray(env.features()["object_pos"])
    aimed = _Aimed(env, puck_start + REACH * np.array([np.sin(heading), np.cos(heading), 0.0]))
    planner, done = WaypointPlanner("push", PLANNER), False
    while not done:
        _, _, terminated, truncated, info = env.step(planner(aimed))
        if info["success"]:
            return True
        done = terminated or truncated
    return False


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=50)
    parser.add_argument("--split", choices=["train", "test"], default="test")
    parser.add_argument("--seed", type=int, default=100)
    parser.add_argument("--episode-steps", type=int, default=150)
    parser.add_argument("--headings", type=float, nargs="+", default=[0.0, 25.0, -25.0, 50.0, -50.0],
                        help="degrees from +y, tried in this order by the carried-on fan")
    args = parser.parse_args()
    task = load_task(TASK)
    env = TaskEnv(task.model_copy(update={"max_episode_steps": args.episode_steps}), TASK, split=args.split, stage=STAGE)
    goals = env.unwrapped.backend.num_goals(args.split)
    hits = np.array([[pushed_to_goal(env, n % goals, args.seed + n, np.radians(h)) for h in args.headings]
                     for n in range(args.trials)])
    env.close()
    by_heading = hits.mean(axis=0)
    found_by = [float(hits[:, :k].any(axis=1).mean()) for k in range(1, len(args.headings) + 1)]
    print_table(["episode of the trial", "heading (deg)", "this heading alone", "carried-on fan: found by then", "memoryless push"],
                [[k, f"{h:+.0f}", f"{by_heading[k - 1]:.2f}", f"{found_by[k - 1]:.2f}", f"{found_by[0]:.2f}"]
                 for k, h in enumerate(args.headings, 1)])
    path = write_result("push_sweep", {
        "task": str(TASK.relative_to(ROOT)), "stage": STAGE, "split": args.split, "trials": args.trials, "seed": args.seed,
        "episode_steps": args.episode_steps, "headings_deg": args.headings, "success_by_heading": by_heading.tolist(),
        "found_by_episode": found_by, "hits": hits.astype(int).tolist()})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
