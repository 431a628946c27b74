"""Simulator backends, one module each, chosen by the `type` of a task's `backend:` block.

Each backend module offers `check_task(task, file) -> list[SpecIssue]`, `create(task, file) ->
Backend` (called only once the checks pass) and `PROVIDES` (the feature names it fills); it is imported only when a task uses it, so validating a Meta-World task never
imports another simulator's packages.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from types import ModuleType

from taskforge.backends.base import Backend, GoalOverride, Split
from taskforge.spec import SpecError, SpecIssue, TaskSpec

_MODULES = {
    "metaworld": "taskforge.backends.metaworld",
    "gymnasium": "taskforge.backends.gymnasium_env",
    "xarm7": "taskforge.backends.xarm7",
}


def _module(task: TaskSpec) -> ModuleType:
    return importlib.import_module(_MODULES[task.backend.type])


def make_backend(task: TaskSpec, file: str | Path) -> Backend:
    module = _module(task)
    issues = module.check_task(task, file)
    if issues:
        raise SpecError(issues)
    return module.create(task, file)


def backend_issues(task: TaskSpec, file: str | Path) -> list[SpecIssue]:
    """Checks that need the backend's simulator package (e.g. known environment names)."""
    return _module(task).check_task(task, file)


def backend_features(task: TaskSpec) -> frozenset[str]:
    return _module(task).PROVIDES


__all__ = ["Backend", "GoalOverride", "Split", "backend_features", "backend_issues", "make_backend"]
