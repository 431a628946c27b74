"""`taskforge inspect`: what an author needs to write a task file from data rather than guesses.

Two views of one task (and stage):

* the compiled MuJoCo model's element names by kind (bodies, geoms, joints, actuators, sites,
  cameras): what `randomization.physics[].names` patterns match, and which camera `render` can use;
* a scripted episode, step by step: every scalar feature the stage's success conditions and
  reward terms read, each reward term's weighted value, the reward and whether the stage's
  success holds, so a threshold is set from what the scripted policy actually reaches.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import mujoco

from taskforge.demos import scripted_policy
from taskforge.envs import TaskEnv
from taskforge.terms import SCALAR_FEATURES

NAME_KINDS = {
    "bodies": mujoco.mjtObj.mjOBJ_BODY,
    "geoms": mujoco.mjtObj.mjOBJ_GEOM,
    "joints": mujoco.mjtObj.mjOBJ_JOINT,
    "actuators": mujoco.mjtObj.mjOBJ_ACTUATOR,
    "sites": mujoco.mjtObj.mjOBJ_SITE,
    "cameras": mujoco.mjtObj.mjOBJ_CAMERA,
}
_COUNTS = {"bodies": "nbody", "geoms": "ngeom", "joints": "njnt", "actuators": "nu", "sites": "nsite", "cameras": "ncam"}


def model_names(env: TaskEnv, task_name: str | None = None) -> dict[str, list[str]]:
    """Named elements of a sub-task's compiled model by kind (unnamed ones left out); empty for
    a backend without a MuJoCo model."""
    model = env.backend.model(task_name or env.backend.task_names[0])
    if model is None:
        return {}
    return {
        kind: [n for i in range(getattr(model, _COUNTS[kind])) if (n := mujoco.mj_id2name(model, obj, i))]
        for kind, obj in NAME_KINDS.items()
    }


@dataclass
class Trace:
    """One scripted episode, a row per step (step 0: after the reset)."""

    policy: str
    columns: list[str]
    rows: list[list[float]]

    def write_csv(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(self.columns)
            writer.writerows(self.rows)

    @property
    def first_success(self) -> int | None:
        """The first step at which the stage's success held, or None."""
        column = self.columns.index("success")
        return next((int(r[0]) for r in self.rows if r[column]), None)

    def table(self, every: int) -> str:
        """Every `every`-th step, the first step the stage succeeds, and the last step."""
        succeed = self.first_success
        chosen = [r for r in self.rows if int(r[0]) % every == 0 or int(r[0]) == succeed or r is self.rows[-1]]
        cells = [self.columns] + [[f"{v:.4g}" if isinstance(v, float) else str(v) for v in r] for r in chosen]
        widths = [max(len(row[i]) for row in cells) for i in range(len(self.columns))]
        lines = ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in cells]
        return "\n".join([lines[0], "  ".join("-" * w for w in widths), *lines[1:]])


def scripted_trace(env: TaskEnv, stage: str, seed: int = 0, goal_index: int = 0) -> Trace:
    """Run the stage's scripted policy (as `taskforge demos` would) for one episode."""
    policy = scripted_policy(env, stage)
    compiled = env.stages[stage]
    features = sorted(compiled.reads & SCALAR_FEATURES) or sorted(
        SCALAR_FEATURES & set(env.features()))
    weights = {t.key: t.weight for t in compiled.terms}
    columns = ["step", *features, *(f"reward/{k}" for k in weights), "reward", "success"]

    def row(step: int, reward: float, info: dict) -> list:
        f = {**env.features(), "stage_success": float(bool(info["success"]))}  # the env adds it, not the backend
        terms = info.get("reward_terms", {})
        return [step, *(float(f[name]) for name in features), *(weights[k] * float(terms.get(k, 0.0)) for k in weights),
                float(reward), int(bool(info["success"]))]

    _, info = env.reset(seed=seed, options={"stage": stage, "goal_index": goal_index})
    policy.reset(env)
    rows = [row(0, 0.0, info)]
    done, step = False, 0
    while not done:
        _, reward, terminated, truncated, info = env.step(policy(env))
        step += 1
        rows.append(row(step, reward, info))
        done = terminated or truncated
    return Trace(policy.name, columns, rows)
