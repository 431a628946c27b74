"""Building envs from task files: the public `taskforge.make`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from gymnasium.spaces import Box

from taskforge.backends import Split
from taskforge.envs.resolve import load_task
from taskforge.envs.task_env import TaskEnv
from taskforge.spec import SpecError, TaskSpec


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
    native: bool | None = None,
) -> TaskEnv:
    """A Gymnasium env for one stage of a task file.

    Args:
        task_file: path to a task YAML.
        stage: stage name; default the first stage.
        split: `train` or `test` (held-out) goals.
        seed: seeds the first `reset()` (goal choice, randomisation, noise).
        task: for a task set (MT10), pin one sub-task; default sample one per episode.
        privileged: add `info["privileged"]` for an asymmetric critic.
        native: compute the suite's own reward and success every step (`info["native_success"]`);
            default only when a stage reads them (they are ~40 % of a Meta-World step).
    """
    spec = load_task(task_file)
    return TaskEnv(spec, task_file, stage=stage, split=split, seed=seed, task_name=task, privileged=privileged, native=native)


@dataclass(frozen=True)
class PhaseShapes:
    observation_space: Box
    action_space: Box
    privileged_size: int
    """The largest `info["privileged"]` of any phase (the critic's extra input)."""
    task_names: list[list[str]]
    """Each phase's sub-task names."""


def probe_phases(
    phases: Sequence[tuple[TaskSpec, str | Path]], privileged: bool, file: str | Path = "<curriculum>"
) -> PhaseShapes:
    """Build each phase's env once to read its spaces; one policy needs the same observation and
    action shapes in every phase, so a mismatch is the curriculum's mistake (`phases[i].task`)."""
    first: TaskEnv | None = None
    sizes, names = [], []
    for i, (task, task_file) in enumerate(phases):
        env = TaskEnv(task, task_file, privileged=privileged)
        sizes.append(env.privileged_size)
        names.append(list(env.backend.task_names))
        env.close()
        if first is None:
            first = env
        elif (env.observation_space.shape, env.action_space.shape) != (first.observation_space.shape, first.action_space.shape):
            raise SpecError.single(
                file, f"phases[{i}].task",
                f"observation/action shapes {env.observation_space.shape}/{env.action_space.shape} differ from phase 1's "
                f"{first.observation_space.shape}/{first.action_space.shape}; one policy needs the same shapes in every phase",
            )
    assert first is not None, "a curriculum has at least one phase"
    return PhaseShapes(first.observation_space, first.action_space, max(sizes), names)
