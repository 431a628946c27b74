"""Meta-World's `step`, without the parts taskforge does not use, and with a cheaper observation.

Measured on pick-place-v3 (benchmarks/env_speed.py has the whole table): of Meta-World's ~1 ms
step, `evaluate_state` (its reward and success) takes ~40 % and `_get_obs` ~30 %, most of that in
scipy's `Rotation.from_matrix(...).as_quat()` (~110 µs for one 3×3 matrix); the physics
(`mj_step` × `frame_skip`) takes ~13 %. taskforge replaces the reward with the stage's own, so:

- `step_without_reward` is Meta-World's `SawyerXYZEnv.step` line for line minus
  `evaluate_state` (keeping the site re-positioning, `mj_forward` and the observation clip, which
  the observation needs: without `mj_forward` it reads positions one substep old). The backend
  calls it unless a stage reads a `native_*` feature.
- `install_fast_observation` gives one env *instance* (never Meta-World's classes or modules, so
  other code in the process still runs Meta-World untouched) two replacements that return the
  same numbers: `_get_quat_objects` with a stand-in for scipy's `Rotation` that runs scipy's own
  algorithm (Shepperd's method, then normalisation) on plain floats, and
  `_get_curr_obs_combined_no_goal` without `np.split`/`hstack` and with cached body ids.

tests/test_metaworld_step.py proves both against untouched Meta-World: observations, positions
and velocities equal over thousands of steps of several envs (the scripted policies, so grasps
happen), with and without randomisation, and every V3 env's observation at random states.
"""

from __future__ import annotations

import math
import types
from typing import Any

import mujoco
import numpy as np


def quat_from_matrix(m: list[float]) -> list[float]:
    """Quaternion (x, y, z, w) of a row-major 3×3 rotation matrix: scipy's
    `Rotation.from_matrix(m).as_quat()` for an orthonormal matrix, operation for operation
    (choose the largest of the diagonal and the trace, build that branch, normalise), so the
    result is the same to the last bit (tested on 20k random rotations). MuJoCo's `xmat` is
    orthonormal to ~1e-16, below scipy's re-orthogonalisation threshold."""
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m
    trace = m00 + m11 + m22
    decision = (m00, m11, m22, trace)
    choice = decision.index(max(decision))  # the first maximum, like numpy's argmax
    if choice == 0:
        q = (1 - trace + 2 * m00, m10 + m01, m20 + m02, m21 - m12)
    elif choice == 1:
        q = (m10 + m01, 1 - trace + 2 * m11, m21 + m12, m02 - m20)
    elif choice == 2:
        q = (m20 + m02, m21 + m12, 1 - trace + 2 * m22, m10 - m01)
    else:
        q = (m21 - m12, m02 - m20, m10 - m01, 1 + trace)
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return [q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm]


class _Rotation:
    """What Meta-World's `_get_quat_objects` methods ask of scipy's `Rotation`: `from_matrix(one
    3×3 matrix).as_quat()`, and nothing else (an env that asked for more would fail loudly in
    the test over every V3 env)."""

    def __init__(self, quat: list[float]):
        self._quat = quat

    @classmethod
    def from_matrix(cls, matrix: Any) -> _Rotation:
        return cls(quat_from_matrix(np.asarray(matrix, dtype=np.float64).reshape(9).tolist()))

    def as_quat(self) -> np.ndarray:
        return np.array(self._quat)


def _with_fast_rotation(method: types.MethodType) -> types.MethodType | None:
    """`method` re-bound with `_Rotation` in place of scipy's in its globals; None when it does
    not use `Rotation` at all (most envs read a body's `xquat` directly)."""
    fn = method.__func__
    if "Rotation" not in fn.__code__.co_names:
        return None
    fast = types.FunctionType(fn.__code__, {**fn.__globals__, "Rotation": _Rotation}, fn.__name__, fn.__defaults__, fn.__closure__)
    return types.MethodType(fast, method.__self__)


def install_fast_observation(env: Any) -> None:
    """Replace two observation helpers on this env instance with ones that return the same
    numbers faster (module doc). Meta-World's own `step`, `reset` and `_get_obs` then use them
    too, so the backend's native path gets faster as well."""
    quat = _with_fast_rotation(env._get_quat_objects)
    if quat is not None:
        env._get_quat_objects = quat
    model, data = env.model, env.data
    hand = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "hand")
    right = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "rightclaw")
    left = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "leftclaw")
    size = env._obs_obj_max_len

    def current_observation() -> np.ndarray:
        """`SawyerXYZEnv._get_curr_obs_combined_no_goal`: hand position, normalised finger
        distance, then each object's position and quaternion, zero-padded to 18 floats."""
        xpos = data.xpos
        apart = np.linalg.norm(xpos[right] - xpos[left])  # the same call as Meta-World's
        out = np.zeros(4 + size)
        out[0:3] = xpos[hand]  # Meta-World's `get_endeff_pos`
        out[3] = min(max(apart / 0.1, 0.0), 1.0)
        pos, quat = env._get_pos_objects(), env._get_quat_objects()
        at = 4
        for k in range(len(pos) // 3):  # position then quaternion, object by object
            out[at:at + 3] = pos[3 * k:3 * k + 3]
            out[at + 3:at + 7] = quat[4 * k:4 * k + 4]
            at += 7
        return out

    env._get_curr_obs_combined_no_goal = current_observation


def step_without_reward(env: Any, action: np.ndarray) -> np.ndarray:
    """Meta-World's `SawyerXYZEnv.step` (metaworld 3.1.1) without `evaluate_state`: the same
    simulation, the same observation (returned), the same env state for the next call."""
    env.set_xyz_action(action[:3])
    env.do_simulation([action[-1], -action[-1]], n_frames=env.frame_skip)
    env.curr_path_length += 1
    # Meta-World: "running the simulator can sometimes mess up site positions"
    for site in env._target_site_config:
        env._set_pos_site(*site)
    if env._did_see_sim_exception:
        return env._last_stable_obs  # Meta-World's answer after a simulator exception
    mujoco.mj_forward(env.model, env.data)  # the observation reads positions after the last substep
    space = env.sawyer_observation_space
    env._last_stable_obs = np.clip(env._get_obs(), a_max=space.high, a_min=space.low, dtype=np.float64)
    return np.array(env._last_stable_obs, dtype=np.float64)
