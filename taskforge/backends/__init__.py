"""Simulator backends, one module each, chosen by the `type` of a task's `backend:` block.

Each backend module offers `check_task(task, file) -> list[SpecIssue]`, `create(task, file) ->
Backend` (called only once the checks pass) and `PROVIDES` (the feature names it fills); it is
imported only when a task uses it, so validating a Meta-World task never imports another
simulator's packages.

`BACKENDS` holds one record per backend: the other tables (scripted policies in
`taskforge.demos`, the default camera of `taskforge render`) read it rather than keeping their
own lists. Adding a backend: its schema in `taskforge/spec/backends.py`, its module here, and
its record below.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from taskforge.backends.base import Backend, GoalOverride, Split
from taskforge.spec import SpecError, SpecIssue, TaskSpec
from taskforge.spec.backends import BACKEND_TYPES


@dataclass(frozen=True)
class BackendInfo:
    """What the rest of taskforge needs to know about a backend without importing it."""

    module: str
    """The module offering `check_task`, `create` and `PROVIDES`."""
    camera: str | None = None
    """Camera `taskforge render` uses by default (None: MuJoCo's free camera, or no rendering)."""
    cartesian_actions: bool = False
    """Its (default) action is a 4-D Cartesian step + gripper (-1 open, +1 close), so the waypoint
    planner of `taskforge.demos` can drive it."""


BACKENDS: dict[str, BackendInfo] = {
    "metaworld": BackendInfo("taskforge.backends.metaworld", camera="corner", cartesian_actions=True),
    "gymnasium": BackendInfo("taskforge.backends.gymnasium_env"),
    # in `control.mode: joint` the xArm7's action is 8-D: `taskforge.demos` checks the shape
    "xarm7": BackendInfo("taskforge.backends.xarm7", camera="front", cartesian_actions=True),
    "point_mass": BackendInfo("taskforge.backends.point_mass"),
}
assert set(BACKENDS) == set(BACKEND_TYPES), "every backend schema (spec/backends.py) needs a record here"


def _module(task: TaskSpec) -> ModuleType:
    return importlib.import_module(BACKENDS[task.backend.type].module)


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


__all__ = ["BACKENDS", "Backend", "BackendInfo", "GoalOverride", "Split", "backend_features", "backend_issues", "make_backend"]
