"""What every MuJoCo backend computes the same way: the stage's goal override, the grasp test,
the distance features, and whether the simulation has blown up. One copy, so the backends cannot
drift apart (they had: only one grasp test skipped contacts without a constraint row).

Importing it also routes MuJoCo's warnings ("Nan, Inf or huge value in QACC…") to Python's
logging (logger `taskforge.mujoco`, once per distinct message) instead of MuJoCo's default,
which prints them and appends them to a `MUJOCO_LOG.TXT` in whatever directory the user runs
from. The env ends such an episode itself (`diverged`) and the trainer counts it."""

from __future__ import annotations

import logging
import math
from collections.abc import Collection

import mujoco
import numpy as np

from taskforge.backends.base import GoalOverride

LOGGER = logging.getLogger("taskforge.mujoco")
_warned: set[str] = set()


def _log_warning(message: str) -> None:
    text = message.split(" Time = ")[0].strip()  # the time stamp makes every message new
    if text not in _warned:
        _warned.add(text)
        LOGGER.warning("MuJoCo: %s (the episode is ended as truncated and counted in unstable_episodes)", text)


mujoco.set_mju_user_warning(_log_warning)

_BAD = sorted(int(w) for w in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL))
assert _BAD == list(range(_BAD[0], _BAD[0] + 3)), "MuJoCo's bad-state warnings are no longer adjacent"
_DIVERGENCE_WARNINGS = slice(_BAD[0], _BAD[0] + 3)
"""A slice, not a list of indices: `diverged` runs every step and fancy indexing costs more."""


def override_goal(goal: np.ndarray, rest: np.ndarray, override: GoalOverride) -> np.ndarray:
    """The goal a stage asks for (`GoalOverrideSpec`): its horizontal distance from the object's
    resting place scaled, its height kept or moved towards the object's or a number (onto it
    with `height_scale` 0)."""
    out = np.array(goal, dtype=float)
    out[:2] = rest[:2] + override.distance_scale * (out[:2] - rest[:2])
    if override.height != "keep":
        plane = rest[2] if override.height == "object" else float(override.height)
        out[2] = plane + override.height_scale * (out[2] - plane)
    return out


def pads_press(data: mujoco.MjData, obj: int | None, left: Collection[int], right: Collection[int]) -> float:
    """1.0 when a geom of each finger pushes on the object with positive normal force (Meta-World's
    `touching_object`). A contact without a constraint row (`efc_address` -1: excluded or not yet
    active) pushes nothing. A plain loop over the few contacts: cheaper than numpy reductions and
    Meta-World's per-contact struct access at this size; it runs every step."""
    if obj is None or data.ncon == 0:
        return 0.0
    contact = data.contact
    efc_force, efc_address = data.efc_force, contact.efc_address
    touch_left = touch_right = False
    for k, (g1, g2) in enumerate(contact.geom.tolist()):
        other = g2 if g1 == obj else g1 if g2 == obj else -1
        if other < 0 or not (other in left or other in right):
            continue
        adr = efc_address[k]
        if adr >= 0 and efc_force[adr] > 0:
            if other in left:
                touch_left = True
            else:
                touch_right = True
    return float(touch_left and touch_right)


def distances(tcp: list[float], obj: list[float], goal: list[float]) -> dict[str, float]:
    """The three distance features, on plain floats (numpy's per-call overhead dominates at
    this size)."""
    return {
        "object_to_goal_distance": math.dist(obj, goal),
        "tcp_to_object_distance": math.dist(tcp, obj),
        "tcp_to_goal_distance": math.dist(tcp, goal),
    }


def diverged(data: mujoco.MjData) -> bool:
    """The simulation blew up since the last reset: MuJoCo flagged a bad acceleration, position or
    velocity (it then silently resets the state, so the episode goes on from nonsense), or the
    velocities are no longer finite (positions: the env checks the observation). Extreme randomisation or actions can cause it; the env ends the
    episode instead of learning from it."""
    return any(data.warning.number[_DIVERGENCE_WARNINGS].tolist()) or not math.isfinite(data.qvel.sum())  # NaN/inf if any entry is
