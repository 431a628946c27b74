"""Curriculum scheduling: which stage and sub-task each episode runs, and when to promote or
demote. It uses only numpy and the spec models, so it can be tested without a simulator."""

from taskforge.curriculum.progress import LearningProgressSampler
from taskforge.curriculum.scheduler import Assignment, CurriculumEvent, CurriculumScheduler

__all__ = ["Assignment", "CurriculumEvent", "CurriculumScheduler", "LearningProgressSampler"]
