"""Building envs from task files: the public `taskforge.make`."""

from __future__ import annotations

from pathlib import Path

from taskforge.backends import Split
from taskforge.envs.resolve import load_task
from taskforge.envs.task_env import TaskEnv
from taskforge.spec import TaskSpec


def check_task_file(task_file: str | Path) -> TaskSpec:
    """Every check `make` would do, including those that need the compiled simulator model
    (randomisation `names` must match bodies, geoms, joints or actuators)."""
    spec = load_task(task_file)
    TaskEnv(spec, task_file).close()
    return spec


def make(
    task_file: str | Path,
    stage: str | None = None,
    split: Split = "train",
    seed: int | None = None,
    task: str | None = None,
    privileged: bool = False,
) -> TaskEnv:
    """A Gymnasium env for one stage of a task file.

    Args:
        task_file: path to a task YAML.
        stage: stage name; default the first stage.
        split: `train` or `test` (held-out) goals.
        seed: seeds the first `reset()` (goal choice, randomisation, noise).
        task: for a task set (MT10), pin one sub-task; default sample one per episode.
        privileged: add `info["privileged"]` for an asymmetric critic.
    """
    spec = load_task(task_file)
    return TaskEnv(spec, task_file, stage=stage, split=split, seed=seed, task_name=task, privileged=privileged)
