"""The Gymnasium env that joins backend, stage terms and randomisation; loading with all checks."""

from taskforge.envs.factory import make
from taskforge.envs.resolve import CurriculumPhase, ResolvedCurriculum, load_curriculum, load_task
from taskforge.envs.task_env import SPLITS, TaskEnv

__all__ = ["SPLITS", "CurriculumPhase", "ResolvedCurriculum", "TaskEnv", "load_curriculum", "load_task", "make"]
