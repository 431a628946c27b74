"""UFACTORY xArm7 + parallel gripper picking a cube, in MuJoCo (`backend: {type: xarm7}`).

Scene and robot
  The backend composes its own scene with `mujoco.MjSpec` (`xarm7_scene.build_scene`): a table
  whose top is at `table_height` (default 0, the world plane of `taskforge/backends/assets/xarm7/scene.xml`), the
  robot from `robot_model` (default the built-in `taskforge/backends/assets/xarm7/xarm7.xml`) standing where its file
  puts `link_base` (z = 0.12) on a pedestal that reaches down to the table, the cube (`cube.size`
  half-side, `cube.mass`), a goal marker (mocap body `goal` with a visual-only site), two lights
  and the cameras `front`, `top`, `side`. `model()` returns this compiled model; the env's
  physics randomiser changes it in place at every reset, before `reset()` runs, so randomised
  masses, friction, damping, servo gains (arm and gripper), gravity and cube size all act.

Names the backend relies on (taskforge's model uses Menagerie's names; only the pads differ):

  | what                      | taskforge `xarm7.xml`              | Menagerie `ufactory_xarm7/xarm7.xml`            |
  |---------------------------|------------------------------------|-------------------------------------------------|
  | arm joints                | `joint1` ... `joint7`              | same                                            |
  | arm position servos       | `act1` ... `act7`                  | same                                            |
  | gripper servo (0 open .. 255 closed, affine bias, on tendon `split`) | `gripper` | same                                   |
  | tool centre point site    | `link_tcp`                         | same                                            |
  | start pose keyframe       | `home`                             | same                                            |
  | finger pad geoms (`pad_geoms`) | `left_finger_pad`, `right_finger_pad` | `left_finger_pad_1`, `left_finger_pad_2`, `right_finger_pad_1`, `right_finger_pad_2` |

  For Menagerie's model (with its `assets/` meshes) write

      backend:
        type: xarm7
        robot_model: path/to/mujoco_menagerie/ufactory_xarm7/xarm7.xml   # relative to the task file
        pad_geoms: {left: [left_finger_pad_1, left_finger_pad_2], right: [right_finger_pad_1, right_finger_pad_2]}

  Its finger joints (`left_driver_joint`, ... hinges) differ from ours (`left_finger_joint`,
  slides) but are not used: the gripper opening is read from the `gripper` actuator's length
  (the `split` tendon, 0 open ... 0.85 closed in both models). `gravity_compensation: true`
  (default) gives Menagerie's links `gravcomp=1` like ours.

Actions (`control.mode`)
  `cartesian` (default), 4 floats in [-1, 1] (Meta-World's shape): TCP target += `max_step_m` *
  (dx, dy, dz), clamped to `control.workspace` (z above the table top) and to `target_lead_m`
  around the measured TCP; mink IK (`xarm7_control.CartesianIK`) solves the 7 arm joint
  targets with the gripper pointing down, written to `act1..7`. `joint`: 8 floats, 7 arm
  joint targets (`joint_targets: delta` (default): += a * `max_joint_step_rad`; `absolute`:
  [-1, 1] -> the actuator's ctrl range) + grip. Grip: -1 = open (ctrl 0) ... +1 = closed
  (ctrl 255), linear; 0 is half closed. Each control step then runs `substeps` `mj_step`s;
  `dt` = 1 / `frequency_hz`. The position servos lag a moving target by about
  kv/kp x velocity = 0.1 s x velocity (4 cm at the full 0.4 m/s); `cartesian_target` is the
  controller's target and `ik_ms_per_step` the mean IK wall time per control step.

Observation (float64 here; the env casts to float32), 28 floats:

  | index   | content                                               |
  |---------|-------------------------------------------------------|
  | 0:3     | TCP (`link_tcp`) position (m, world)                  |
  | 3       | gripper opening, 0 closed ... 1 open                  |
  | 4:7     | cube position                                         |
  | 7:11    | cube orientation quaternion (w, x, y, z)              |
  | 11:14   | goal position (`goal_slice`; zeroed by the env when the goal is hidden) |
  | 14:21   | arm joint angles `joint1..7` (rad)                    |
  | 21:28   | arm joint velocities (rad/s)                          |

  The cube's velocity is *not* observed: it is privileged (`object_velocity`, which the env puts
  in `info["privileged"]` with the goal and the physics draws).

Features: every shared feature. `tcp_pos` = `link_tcp`; `object_grasped` = a geom of each
  finger's `pad_geoms` touches the cube with positive normal force; `object_height` = cube z
  minus its z after the reset's settling; `gripper_opening` as in the observation;
  `object_velocity` = the free joint's linear velocity; `native_reward` = 0 (the robot has no
  reward of its own), `native_return` = their sum (0), `native_success` = cube within
  `success_distance` (5 cm) of the goal.

Goals and reset
  Each split is a fixed list of entries (cube start x, y; goal x, y, z above the table),
  generated from `goals.seed` (`xarm7_scene.make_goal_sets`); held-out test goals come from the
  other colour of a 3-D checkerboard over the goal region, at least 2 x `goal_split.margin` from
  every train goal; with `goals.train.draw: fresh` each training task instance draws its own
  entry by the train split's rule (`xarm7_scene.fresh_train_entry`), so it keeps that gap.
  Reset: arm at `home` (gripper open), cube at the entry's start resting on
  the table (its current, possibly randomised size; with `randomization.object_start: random`
  drawn afresh over `object_region`, at least `min_goal_distance` from the goal), goal at the
  entry's goal moved by the stage's goal override (exactly as Meta-World's backend:
  `height: object` = the cube's rest height, `distance_scale` pulls it towards the cube
  horizontally), `settle_steps` physics steps; the TCP target starts at the measured TCP.
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
from gymnasium.spaces import Box

from taskforge.backends.base import GoalOverride, Split
from taskforge.backends.mujoco_common import distances, override_goal, pads_press
from taskforge.backends.xarm7_control import CartesianIK
from taskforge.backends.xarm7_scene import (
    ARM_ACTUATORS,
    ARM_JOINTS,
    GOAL_BODY,
    GRIPPER_ACTUATOR,
    OBJECT_GEOM,
    OBJECT_JOINT,
    TCP_SITE,
    GoalRegionTooSmall,
    GoalSet,
    build_ik_model,
    build_scene,
    fresh_train_entry,
    home_qpos,
    load_robot,
    make_goal_sets,
    place_cubes,
    required_names,
    robot_path,
)
from taskforge.spec import SpecIssue, TaskSpec, did_you_mean
from taskforge.spec.backends import XArm7BackendSpec
from taskforge.spec.task import GoalsSpec
from taskforge.terms import ENV_FEATURES, FEATURES, Features

PROVIDES = frozenset(FEATURES) - ENV_FEATURES
OBS_SIZE = 28
GOAL_SLICE = slice(11, 14)
TASK_NAME = "xarm7"


class XArm7Backend:
    provides = PROVIDES
    native = True  # its native features are a distance test: always computed
    goal_slice = GOAL_SLICE
    obs_size = OBS_SIZE

    def __init__(self, spec: XArm7BackendSpec, goals: GoalsSpec, file: str | Path = "<task>"):
        self.spec = spec
        self.task_names = [TASK_NAME]
        control = spec.control
        self.cartesian = control.mode == "cartesian"
        self.action_space = Box(-1.0, 1.0, (4 if self.cartesian else 8,), np.float32)
        self.dt = 1.0 / control.frequency_hz
        self.substeps = control.physics_substeps

        robot = load_robot(robot_path(spec, file))
        ik_model = build_ik_model(robot)
        self.scene = build_scene(spec, robot)
        m = self._model = self.scene
        self._data = mujoco.MjData(m)
        self._train, self._test = make_goal_sets(spec, goals.seed, goals.train.count, goals.test.count)
        self._fresh_train = goals.train.draw == "fresh"

        # Ids, resolved once.
        self._arm_qadr = np.array([m.jnt_qposadr[m.joint(j).id] for j in ARM_JOINTS])
        self._arm_dadr = np.array([m.jnt_dofadr[m.joint(j).id] for j in ARM_JOINTS])
        self._arm_act = np.array([m.actuator(a).id for a in ARM_ACTUATORS])
        self._ctrl_low = m.actuator_ctrlrange[self._arm_act, 0].copy()
        self._ctrl_high = m.actuator_ctrlrange[self._arm_act, 1].copy()
        self._grip = m.actuator(GRIPPER_ACTUATOR).id
        # grip -1 .. 1 -> the gripper's ctrl range (0 = open .. 255 = closed), linearly.
        self._grip_low = float(m.actuator_ctrlrange[self._grip, 0])
        self._grip_scale = float(m.actuator_ctrlrange[self._grip, 1] - self._grip_low) / 2.0
        # Tendon length at full closure: the servo's set point at the top of its ctrl range.
        gain, bias = float(m.actuator_gainprm[self._grip, 0]), float(m.actuator_biasprm[self._grip, 1])
        closed = float(m.actuator_ctrlrange[self._grip, 1]) * gain / -bias if bias < 0 else 0.85
        self._inv_closed = 1.0 / closed if closed > 0 else 1.0
        self._tcp = m.site(TCP_SITE).id
        self._obj_geom = m.geom(OBJECT_GEOM).id
        obj_joint = m.joint(OBJECT_JOINT).id
        self._obj_qadr = int(m.jnt_qposadr[obj_joint])
        self._obj_dadr = int(m.jnt_dofadr[obj_joint])
        self._goal_mocap = int(m.body_mocapid[m.body(GOAL_BODY).id])
        self._left = frozenset(m.geom(g).id for g in spec.pad_geoms.left)
        self._right = frozenset(m.geom(g).id for g in spec.pad_geoms.right)
        self._home = home_qpos(m)
        self._table = spec.table_height
        ws = control.workspace
        self._ws_low = (ws.x[0], ws.y[0], ws.z[0] + self._table)
        self._ws_high = (ws.x[1], ws.y[1], ws.z[1] + self._table)

        self.ik = CartesianIK(
            ik_model, self._home, iterations=control.ik_iterations, tolerance=control.ik_tolerance_m,
            damping=control.ik_damping, orientation_cost=control.orientation_cost, posture_cost=control.posture_cost,
        )
        self._target = np.zeros(3)
        self._q_target = self._home.copy()
        self._goal = np.zeros(3)
        self._rest = np.zeros(3)
        self._native_success = 0.0

    # -- models -------------------------------------------------------------------------------

    def model(self, task_name: str) -> mujoco.MjModel:
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        return self._data

    def object_geoms(self, task_name: str) -> list[str]:
        return [OBJECT_GEOM]

    def num_goals(self, split: Split) -> int:
        return len(self._train.goals if split == "train" else self._test.goals)

    def goal_entry(self, split: Split, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(cube start x, y; goal x, y, z in world coordinates) of an entry, before overrides."""
        return self._world_entry(self._train if split == "train" else self._test, index)

    def _world_entry(self, entries: GoalSet, index: int) -> tuple[np.ndarray, np.ndarray]:
        goal = entries.goals[index].copy()
        goal[2] += self._table
        return entries.objects[index].copy(), goal

    @property
    def cartesian_target(self) -> np.ndarray:
        """The Cartesian controller's current TCP target (world, m); a copy."""
        return self._target.copy()

    @property
    def ik_ms_per_step(self) -> float:
        """Mean wall-clock milliseconds of IK per Cartesian control step so far."""
        return self.ik.ms_per_call

    # -- episode ------------------------------------------------------------------------------

    def reset(
        self, task_name: str, split: Split, goal_index: int, goal: GoalOverride,
        task_rng: np.random.Generator | None = None,
    ) -> np.ndarray:
        m, d = self._model, self._data
        if split == "train" and self._fresh_train and task_rng is not None:
            obj_xy, goal_pos = self._world_entry(fresh_train_entry(self.spec, task_rng), 0)
        else:
            obj_xy, goal_pos = self.goal_entry(split, goal_index)
            if task_rng is not None:
                obj_xy = place_cubes(self.spec, goal_pos[None], task_rng)[0]
        mujoco.mj_resetData(m, d)
        d.qpos[self._arm_qadr] = self._home
        d.ctrl[self._arm_act] = self._home
        d.ctrl[self._grip] = 0.0
        a = self._obj_qadr
        # Resting on the table at its current (possibly randomised) half-height, unrotated.
        d.qpos[a : a + 7] = (obj_xy[0], obj_xy[1], self._table + m.geom_size[self._obj_geom, 2], 1.0, 0.0, 0.0, 0.0)
        d.mocap_pos[self._goal_mocap] = goal_pos
        if self.spec.settle_steps:
            mujoco.mj_step(m, d, nstep=self.spec.settle_steps)
        mujoco.mj_forward(m, d)
        rest = d.qpos[a : a + 3].copy()
        self._rest = rest
        if not goal.is_identity:
            goal_pos = override_goal(goal_pos, rest, goal)
            d.mocap_pos[self._goal_mocap] = goal_pos
        self._goal = goal_pos
        self._target = d.site_xpos[self._tcp].copy()
        self._q_target = d.qpos[self._arm_qadr].copy()
        self.ik.reset(self._q_target)
        self._update_success()
        return self._observation()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, bool]:
        m, d = self._model, self._data
        a = np.asarray(action, dtype=np.float64)
        if self.cartesian:
            d.ctrl[self._arm_act] = self.ik.solve(self._next_target(a))
        elif self.spec.control.joint_targets == "delta":
            q = self._q_target
            q += self.spec.control.max_joint_step_rad * a[:7]
            np.clip(q, self._ctrl_low, self._ctrl_high, out=q)
            d.ctrl[self._arm_act] = q
        else:
            d.ctrl[self._arm_act] = self._ctrl_low + (a[:7] + 1.0) * 0.5 * (self._ctrl_high - self._ctrl_low)
        d.ctrl[self._grip] = self._grip_low + (float(a[-1]) + 1.0) * self._grip_scale
        mujoco.mj_step(m, d, nstep=self.substeps)
        # mj_step leaves positions-derived quantities one physics step behind qpos; refresh them.
        mujoco.mj_kinematics(m, d)
        self._update_success()
        return self._observation(), False

    def _next_target(self, a: np.ndarray) -> np.ndarray:
        """Move the TCP target by the action, keep it in the workspace and near the TCP."""
        step = self.spec.control.max_step_m
        lead = self.spec.control.target_lead_m
        tx, ty, tz = self._target.tolist()
        dx, dy, dz = a[:3].tolist()
        lo, hi = self._ws_low, self._ws_high
        t = [min(max(tx + step * dx, lo[0]), hi[0]), min(max(ty + step * dy, lo[1]), hi[1]),
             min(max(tz + step * dz, lo[2]), hi[2])]
        p = self._data.site_xpos[self._tcp].tolist()
        gap = math.dist(t, p)
        if gap > lead:
            s = lead / gap
            t = [p[i] + s * (t[i] - p[i]) for i in range(3)]
        self._target[:] = t
        return self._target

    def _update_success(self) -> None:
        a = self._obj_qadr
        dist = math.dist(self._data.qpos[a : a + 3].tolist(), self._goal.tolist())
        self._native_success = float(dist < self.spec.success_distance)

    def _observation(self) -> np.ndarray:
        d = self._data
        a = self._obj_qadr
        obs = np.empty(OBS_SIZE)
        obs[0:3] = d.site_xpos[self._tcp]
        obs[3] = self._opening()
        obs[4:11] = d.qpos[a : a + 7]
        obs[11:14] = self._goal
        obs[14:21] = d.qpos[self._arm_qadr]
        obs[21:28] = d.qvel[self._arm_dadr]
        return obs

    def _opening(self) -> float:
        return min(max(1.0 - float(self._data.actuator_length[self._grip]) * self._inv_closed, 0.0), 1.0)

    def features(self) -> Features:
        # Plain-float arithmetic on 3-vectors: numpy's per-call overhead dominates at this size.
        d = self._data
        a, v = self._obj_qadr, self._obj_dadr
        tcp = d.site_xpos[self._tcp].copy()
        obj = d.qpos[a : a + 3].copy()
        tcp_l, obj_l, goal_l = tcp.tolist(), obj.tolist(), self._goal.tolist()
        return {
            "tcp_pos": tcp,
            "object_pos": obj,
            "goal_pos": self._goal.copy(),
            "gripper_opening": self._opening(),
            "object_grasped": pads_press(d, self._obj_geom, self._left, self._right),
            "object_height": obj_l[2] - float(self._rest[2]),
            **distances(tcp_l, obj_l, goal_l),
            "object_velocity": d.qvel[v : v + 3].copy(),
            "native_reward": 0.0,
            "native_success": self._native_success,
            "native_return": 0.0,
        }

    def close(self) -> None:
        pass


# --- checks and construction ------------------------------------------------------------------


def check_task(task: TaskSpec, file: str | Path) -> list[SpecIssue]:
    """Robot file, the names the backend needs, and that the goal sets can be drawn."""
    spec: XArm7BackendSpec = task.backend
    file_s = str(file)
    issues: list[SpecIssue] = []
    path = robot_path(spec, file)
    if not path.is_file():
        return [SpecIssue(file_s, "backend.robot_model", f"file not found: {path}")]
    try:
        model = build_scene(spec, load_robot(path))
    except ValueError as exc:  # MuJoCo's parse/compile errors: a broken or incompatible robot file
        msg = str(exc).strip().replace("\n", " ")
        return [SpecIssue(file_s, "backend.robot_model", f"MuJoCo could not load {path} into the scene: {msg}")]
    for field, kind, name in required_names(spec):
        if mujoco.mj_name2id(model, kind, name) < 0:
            what = kind.name[6:].lower()
            issues.append(SpecIssue(file_s, f"backend.{field}", f"{path.name} has no {what} '{name}'; {_known(model, kind, name)}"))
    if not issues:
        grip = model.actuator(GRIPPER_ACTUATOR).id
        if model.actuator_biastype[grip] != mujoco.mjtBias.mjBIAS_AFFINE or model.actuator_biasprm[grip, 1] >= 0:
            issues.append(SpecIssue(file_s, "backend.robot_model", f"{path.name}: actuator 'gripper' must be a position servo (affine bias, biasprm[1] < 0)"))
    try:
        make_goal_sets(spec, task.goals.seed, task.goals.train.count, task.goals.test.count)
    except GoalRegionTooSmall as exc:
        issues.append(SpecIssue(file_s, "backend.goal_region", str(exc)))
    return issues


def _known(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> str:
    """The model's names of that kind: a close match first, then (for geoms, of which a robot
    has many) those that look like finger pads, else the first 200 characters of them all."""
    count = {mujoco.mjtObj.mjOBJ_JOINT: model.njnt, mujoco.mjtObj.mjOBJ_ACTUATOR: model.nu,
             mujoco.mjtObj.mjOBJ_SITE: model.nsite, mujoco.mjtObj.mjOBJ_GEOM: model.ngeom}[kind]
    names = [n for n in (mujoco.mj_id2name(model, kind, i) for i in range(count)) if n]
    what = kind.name[6:].lower()
    if kind == mujoco.mjtObj.mjOBJ_GEOM:
        pads = [n for n in names if "pad" in n or "finger" in n]
        if pads:
            return f"geoms named like finger pads: {', '.join(pads)}{did_you_mean(name, names)}"
    text = ", ".join(names)
    text = text if len(text) <= 200 else text[:200].rsplit(", ", 1)[0] + ", ..."
    return f"its {what}s include {text}{did_you_mean(name, names)}"


def create(task: TaskSpec, file: str | Path) -> XArm7Backend:
    """The backend of a task that passed `check_task` (see `taskforge.backends.make_backend`)."""
    return XArm7Backend(task.backend, task.goals, file)
