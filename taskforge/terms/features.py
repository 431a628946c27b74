"""The feature names every backend exposes, so reward terms and success conditions can be
written once and run on any simulator.

A features dict maps these names to floats (scalars) or small float arrays (vectors). Backends
fill it after each step; the env adds `action` and `stage_success`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FeatureValue = float | np.ndarray
Features = dict[str, FeatureValue]


@dataclass(frozen=True)
class FeatureInfo:
    size: int
    """1 for a scalar (a Python float in the dict), else the length of the vector (0: depends on
    the backend)."""
    doc: str


FEATURES: dict[str, FeatureInfo] = {
    "tcp_pos": FeatureInfo(3, "tool-centre-point position between the fingers (m, world frame)"),
    "object_pos": FeatureInfo(3, "position of the main object (m)"),
    "goal_pos": FeatureInfo(3, "position of the goal (m), whether or not the agent observes it"),
    "gripper_opening": FeatureInfo(1, "0 = fingers closed, 1 = fully open"),
    "object_grasped": FeatureInfo(1, "1 when both finger pads press on the object, else 0"),
    "object_height": FeatureInfo(1, "height of the object above where it rested at reset (m)"),
    "object_to_goal_distance": FeatureInfo(1, "|object_pos - goal_pos| (m)"),
    "tcp_to_object_distance": FeatureInfo(1, "|tcp_pos - object_pos| (m)"),
    "tcp_to_goal_distance": FeatureInfo(1, "|tcp_pos - goal_pos| (m)"),
    "object_velocity": FeatureInfo(3, "linear velocity of the object (m/s); privileged"),
    "action": FeatureInfo(0, "the action the agent chose this step, before noise and latency (4-D on Meta-World and xArm7 Cartesian, 8-D in xArm7 joint mode)"),
    "native_reward": FeatureInfo(1, "the simulator suite's own reward (Meta-World's v2 reward)"),
    "native_success": FeatureInfo(1, "the simulator suite's own success flag (Meta-World's `success`)"),
    "native_return": FeatureInfo(1, "sum of `native_reward` so far this episode (e.g. LunarLander 'solved' at 200)"),
    "stage_success": FeatureInfo(1, "1 when the current stage's success condition holds"),
    "tcp_to_goal_progress": FeatureInfo(1, "how much closer (m) the tool came to the goal this step than ever before in the episode; 0 when it did not"),
    "object_to_goal_progress": FeatureInfo(1, "how much closer (m) the object came to the goal this step than ever before in the episode; 0 when it did not"),
    "tcp_to_object_progress": FeatureInfo(1, "how much closer (m) the tool came to the object this step than ever before in the episode; 0 when it did not"),
}

PROGRESS_FEATURES: dict[str, str] = {
    "tcp_to_goal_progress": "tcp_to_goal_distance",
    "object_to_goal_progress": "object_to_goal_distance",
    "tcp_to_object_progress": "tcp_to_object_distance",
}
"""Record-distance features and the distance each follows. The env fills them (it alone sees
the episode's history) on any backend that provides the distance. Why: a term of the current
distance pays for *being* near the goal, so with the goal hidden, hovering mid-box out-earns a
search; a term of the record pays only for coming nearer than before, so over an episode it
sums to start distance - closest distance, which a sweep that passes the goal maximises."""
GOAL_FEATURES = frozenset({"goal_pos", "object_to_goal_distance", "tcp_to_goal_distance", "native_success",
                           *(p for p, d in PROGRESS_FEATURES.items() if d in {"object_to_goal_distance", "tcp_to_goal_distance"})})
"""Features that depend on where the goal is (Meta-World's own success flag measures to its goal):
a success condition on one of them cannot be met on a held-out goal the policy neither sees nor
can infer."""
NATIVE_FEATURES = frozenset({"native_reward", "native_success", "native_return"})
"""The simulator suite's own reward and success: a backend may skip computing them (Meta-World:
~40 % of its step) unless a stage reads one (`Backend.native`)."""
STEP_FEATURES = frozenset({"action", "stage_success"})
"""Filled by the env itself on every backend."""
ENV_FEATURES = STEP_FEATURES | frozenset(PROGRESS_FEATURES)
"""Filled by the env itself: `STEP_FEATURES` on every backend, a progress feature where the
backend provides its distance (`env_features`)."""
SCALAR_FEATURES = frozenset(name for name, info in FEATURES.items() if info.size == 1)


def env_features(provides: frozenset[str]) -> frozenset[str]:
    """The features the env adds on a backend that `provides` these."""
    return STEP_FEATURES | {p for p, d in PROGRESS_FEATURES.items() if d in provides}
