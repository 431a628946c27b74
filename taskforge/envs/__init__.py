"""The Gymnasium env that joins backend, stage terms and randomisation; loading with all checks."""

from taskforge.envs.factory import PhaseShapes, check_task_file, make, probe_phases
from taskforge.envs.phased import PhasedEnv
from taskforge.envs.resolve import CurriculumPhase, ResolvedCurriculum, load_curriculum, load_task
from taskforge.envs.task_env import SPLITS, TaskEnv

__all__ = ["SPLITS", "CurriculumPhase", "PhaseShapes", "PhasedEnv", "probe_phases", "ResolvedCurriculum", "TaskEnv", "check_task_file", "load_curriculum", "load_task", "make"]
