"""Schema of a task file's `backend:` block: one model per simulator, joined in the tagged union
`BackendSpec` (by `type`). Adding a backend adds its model here and to the union; `BACKEND_TYPES`
is read from the union, so the names are written once.
"""

from __future__ import annotations

import math
import typing
from typing import Annotated, Any, Literal

from pydantic import Field, model_validator

from taskforge.spec.common import StrictModel


class MetaWorldBackendSpec(StrictModel):
    """A Meta-World v3 environment, or a set of them (MT10)."""

    type: Literal["metaworld"]
    env: str | None = None
    """One v3 environment name, e.g. `pick-place-v3` (ML1/MT1 style)."""
    task_set: Literal["mt10"] | None = None
    """A named set of environments; each keeps its own ML1 train/test goal split."""
    task_id_in_obs: bool = True
    """For task sets: append a one-hot of the sub-task to the observation (the MT10 convention)."""

    def describe(self) -> str:
        """One line for summaries (`taskforge validate`, `taskforge tasks`)."""
        return self.env if self.env else f"task set {self.task_set}"

    @model_validator(mode="after")
    def _one_source(self) -> MetaWorldBackendSpec:
        if (self.env is None) == (self.task_set is None):
            raise ValueError("give exactly one of 'env' (one environment) or 'task_set' (e.g. mt10)")
        return self


class GymnasiumBackendSpec(StrictModel):
    """Any registered Gymnasium env with a Box action space (e.g. LunarLanderContinuous-v3), as a
    sanity check that the agent learns outside robotics. Its 'goals' are reset seeds."""

    type: Literal["gymnasium"]
    env: str
    kwargs: dict[str, Any] = Field(default_factory=dict)
    """Keyword arguments for `gymnasium.make`."""

    def describe(self) -> str:
        """One line for summaries (`taskforge validate`, `taskforge tasks`)."""
        return self.env


Interval = tuple[float, float]
"""`[low, high]` in metres (checked: finite, low <= high)."""


def _check_intervals(model: StrictModel, names: tuple[str, ...]) -> None:
    for name in names:
        low, high = getattr(model, name)
        if not (math.isfinite(low) and math.isfinite(high)):
            raise ValueError(f"'{name}' must be two finite numbers [low, high]")
        if low > high:
            raise ValueError(f"'{name}': low ({low:g}) must be <= high ({high:g})")


class XArm7PadGeomsSpec(StrictModel):
    """The finger-pad geoms that must both press on the cube for `object_grasped`.

    Defaults are taskforge's model (`taskforge/backends/assets/xarm7/xarm7.xml`). MuJoCo Menagerie's
    `ufactory_xarm7/xarm7.xml` has two pad boxes per finger:
    `{left: [left_finger_pad_1, left_finger_pad_2], right: [right_finger_pad_1, right_finger_pad_2]}`.
    """

    left: list[str] = Field(default_factory=lambda: ["left_finger_pad"], min_length=1)
    """Geoms of the left finger (any of them touching counts as the left finger touching)."""
    right: list[str] = Field(default_factory=lambda: ["right_finger_pad"], min_length=1)
    """Geoms of the right finger."""


class XArm7WorkspaceSpec(StrictModel):
    """Box that the Cartesian TCP target is clamped to. x, y in world metres; z in metres
    **above the table top** (so it follows `table_height`)."""

    x: Interval = (0.20, 0.65)
    y: Interval = (-0.35, 0.35)
    z: Interval = (0.005, 0.40)

    @model_validator(mode="after")
    def _ordered(self) -> XArm7WorkspaceSpec:
        _check_intervals(self, ("x", "y", "z"))
        return self


class XArm7ControlSpec(StrictModel):
    """How an action becomes actuator commands, and how often.

    `cartesian`: action (dx, dy, dz, grip) in [-1, 1]^4. The TCP target moves by
    `max_step_m * (dx, dy, dz)` per control step (clamped to `workspace` and to within
    `target_lead_m` of the measured TCP), mink IK turns it into the 7 arm joint targets
    (gripper pointing straight down), written to the position servos `act1..act7`.
    `joint`: action (a1..a7, grip) in [-1, 1]^8, see `joint_targets`. In both modes grip
    -1 = open (gripper ctrl 0) ... +1 = closed (ctrl 255), linearly.

    Timing: one control step lasts `1 / frequency_hz` s (the env's `dt`) and runs `substeps`
    physics steps. Give at most one of `substeps` and `timestep`: with `substeps` the physics
    timestep is `1 / (frequency_hz * substeps)`; otherwise `timestep` (default 0.002 s) is used
    and `substeps = 1 / (frequency_hz * timestep)`, which must be a whole number.
    """

    mode: Literal["cartesian", "joint"] = "cartesian"
    """`cartesian` (4-D, Meta-World's shape, solved by IK) or `joint` (8-D joint targets)."""
    frequency_hz: float = Field(default=20.0, gt=0.0, le=1000.0)
    """Control steps per simulated second."""
    substeps: int | None = Field(default=None, ge=1, le=1000)
    """Physics steps per control step; null = derived from `timestep`."""
    timestep: float | None = Field(default=None, gt=0.0)
    """Physics timestep (s); null = 0.002 unless `substeps` is given. Must be 0.0005 ... 0.005."""
    max_step_m: float = Field(default=0.02, gt=0.0, le=0.1)
    """Cartesian: TCP target displacement (m) per control step at action 1."""
    target_lead_m: float = Field(default=0.05, gt=0.0, le=0.5)
    """Cartesian: the target is kept within this distance (m) of the measured TCP, so pushing
    against the table or a stuck object does not wind the target up."""
    workspace: XArm7WorkspaceSpec = XArm7WorkspaceSpec()
    """Cartesian: box the TCP target is clamped to."""
    ik_iterations: int = Field(default=1, ge=1, le=100)
    """Cartesian: at most this many mink IK iterations (one QP each) per control step. Each step
    warm-starts from the previous solution, so the solution keeps converging over steps (1 =
    one differential-IK step per control step, as in mink's examples: ~2 mm residual right
    after a full 2 cm move, far below the servos' tracking lag, and < 0.1 mm once the target
    holds); it stops early once within `ik_tolerance_m`, so a held target costs no QP."""
    ik_tolerance_m: float = Field(default=1e-4, gt=0.0, le=0.01)
    """Cartesian: IK stops iterating when the TCP position error is below this (m) and the
    orientation error below 10x this (rad)."""
    ik_damping: float = Field(default=1e-3, ge=0.0, le=10.0)
    """Cartesian: Levenberg-Marquardt damping of the IK (mink's `lm_damping` of the frame task
    and the QP's damping)."""
    orientation_cost: float = Field(default=1.0, ge=0.0, le=100.0)
    """Cartesian: weight of the 'pointing straight down' orientation relative to position (1)."""
    posture_cost: float = Field(default=1e-3, ge=0.0, le=10.0)
    """Cartesian: weight of the posture task that pulls the redundant joint towards `home`."""
    joint_targets: Literal["delta", "absolute"] = "delta"
    """Joint mode: `delta`: target += a * max_joint_step_rad (action 0 holds still);
    `absolute`: a in [-1, 1] maps linearly onto each actuator's control range (the joint range)."""
    max_joint_step_rad: float = Field(default=0.05, gt=0.0, le=1.0)
    """Joint mode, `delta`: joint-target change (rad) per control step at action 1."""

    @model_validator(mode="after")
    def _timing(self) -> XArm7ControlSpec:
        if self.substeps is not None and self.timestep is not None:
            raise ValueError("give at most one of 'substeps' and 'timestep' (the other follows from frequency_hz)")
        ts = self.physics_timestep
        if not 0.0005 <= ts <= 0.005 + 1e-12:
            raise ValueError(f"the physics timestep 1/(frequency_hz*substeps) = {ts:.6g} s must be within 0.0005 ... 0.005 s")
        if self.substeps is None:
            ratio = 1.0 / (self.frequency_hz * ts)
            if ratio < 0.5 or abs(ratio - round(ratio)) > 1e-6 * ratio:
                raise ValueError(
                    f"1/(frequency_hz*timestep) = {ratio:g} is not a whole number of physics steps; "
                    "change frequency_hz or timestep, or give 'substeps'"
                )
        return self

    @property
    def physics_timestep(self) -> float:
        if self.substeps is not None:
            return 1.0 / (self.frequency_hz * self.substeps)
        return self.timestep if self.timestep is not None else 0.002

    @property
    def physics_substeps(self) -> int:
        if self.substeps is not None:
            return self.substeps
        return max(1, round(1.0 / (self.frequency_hz * self.physics_timestep)))


class XArm7CubeSpec(StrictModel):
    """The object: a cube resting on the table."""

    size: float = Field(default=0.02, ge=0.01, le=0.04)
    """Half the side length (m); 0.02 = a 4 cm cube. The gripper opens to 88 mm."""
    mass: float = Field(default=0.1, gt=0.0, le=2.0)
    """kg."""
    friction: float = Field(default=1.0, ge=0.0, le=5.0)
    """Sliding friction coefficient (the pads' own friction, 1.5, wins in pad contacts)."""


class XArm7ObjectRegionSpec(StrictModel):
    """Where the cube starts (world x, y in m); it rests on the table, unrotated."""

    x: Interval = (0.30, 0.60)
    y: Interval = (-0.25, 0.25)

    @model_validator(mode="after")
    def _ordered(self) -> XArm7ObjectRegionSpec:
        _check_intervals(self, ("x", "y"))
        return self


class XArm7GoalRegionSpec(StrictModel):
    """Where goals are drawn: world x, y (m) and z in m **above the table top**."""

    x: Interval = (0.30, 0.60)
    y: Interval = (-0.25, 0.25)
    z: Interval = (0.05, 0.30)

    @model_validator(mode="after")
    def _ordered(self) -> XArm7GoalRegionSpec:
        _check_intervals(self, ("x", "y", "z"))
        return self


class XArm7GoalSplitSpec(StrictModel):
    """How the held-out test goals are kept apart from the train goals: the goal region is cut
    into cubic cells of side `cell` coloured like a 3-D checkerboard; train goals are drawn
    from the even cells, test goals from the odd ones, each at least `margin` inside its cell,
    so every test goal is at least 2 x `margin` from every train goal."""

    cell: float = Field(default=0.05, gt=0.0, le=1.0)
    """Checkerboard cell side (m)."""
    margin: float = Field(default=0.005, ge=0.0, le=0.1)
    """Distance (m) a goal keeps from its cell's faces; must be < cell / 2."""

    @model_validator(mode="after")
    def _margin(self) -> XArm7GoalSplitSpec:
        if self.margin * 2 >= self.cell:
            raise ValueError(f"'margin' ({self.margin:g}) must be < cell / 2 ({self.cell / 2:g})")
        return self


class XArm7BackendSpec(StrictModel):
    """UFACTORY xArm7 with a parallel gripper, a cube on a table and a goal, in MuJoCo.

    The scene (table, cube, goal marker, lights, cameras) is composed by the backend with
    `mujoco.MjSpec` around the robot loaded from `robot_model`, so task variants change the
    cube, table and regions with YAML only. Goal set entry `i` of a split fixes both the cube's
    start and the goal (like Meta-World's ML1 tasks). See `taskforge/backends/xarm7.py`.
    """

    type: Literal["xarm7"]
    robot_model: str | None = None
    """MJCF file of the robot, relative to the task file; null = taskforge's built-in
    `taskforge/backends/assets/xarm7/xarm7.xml`. Menagerie's `ufactory_xarm7/xarm7.xml` (with its meshes) works as
    is; set `pad_geoms` for it. The file must have joints `joint1..7`, position actuators
    `act1..7` and `gripper` (0 = open .. 255 = closed, on a tendon), site `link_tcp`, and a
    `home` keyframe (else the arm starts at qpos 0)."""
    pad_geoms: XArm7PadGeomsSpec = XArm7PadGeomsSpec()
    """Finger-pad geom names for `object_grasped`."""
    gravity_compensation: bool = True
    """Set `gravcomp=1` on every robot body (the real xArm controller compensates gravity;
    taskforge's model already has it, Menagerie's does not). false keeps the file's values."""
    control: XArm7ControlSpec = XArm7ControlSpec()
    table_height: float = Field(default=0.0, ge=-0.10, le=0.10)
    """World z (m) of the table top. The robot base stays where the robot file puts it (world
    coordinates of the TCP are the robot file's); the pedestal under it grows or shrinks."""
    cube: XArm7CubeSpec = XArm7CubeSpec()
    object_region: XArm7ObjectRegionSpec = XArm7ObjectRegionSpec()
    goal_region: XArm7GoalRegionSpec = XArm7GoalRegionSpec()
    min_goal_distance: float = Field(default=0.10, ge=0.0, le=1.0)
    """Smallest horizontal distance (m) between the cube's start and the goal of an entry."""
    goal_split: XArm7GoalSplitSpec = XArm7GoalSplitSpec()
    """How held-out test goals are separated from train goals."""
    success_distance: float = Field(default=0.05, gt=0.0, le=1.0)
    """`native_success` = 1 when the cube is within this distance (m) of the goal."""
    settle_steps: int = Field(default=20, ge=0, le=10_000)
    """Physics steps run at reset (arm at home, gripper open) so the cube settles."""

    def describe(self) -> str:
        """One line for summaries (`taskforge validate`, `taskforge tasks`)."""
        model = self.robot_model or "built-in robot"
        return (
            f"{model}, {self.control.mode} control at {self.control.frequency_hz:g} Hz, table top z={self.table_height:g}, "
            f"cube {200 * self.cube.size:g} cm {self.cube.mass:g} kg"
        )


class PointMassBackendSpec(StrictModel):
    """A point robot in the plane that starts at the origin and must reach a goal on an arc
    around it: the classic meta-RL testbed (Finn et al. 2017's 2-D navigation; the sparse
    semicircle of Rakelly et al. 2019 and Zintgraf et al. 2020). No physics engine: a step is
    a few numpy operations, so meta-RL can be checked in minutes. See
    `taskforge/backends/point_mass.py`."""

    type: Literal["point_mass"]
    goal_radius: float = Field(default=1.0, gt=0.0, le=10.0)
    """Distance of every goal from the start (m)."""
    goal_arc: Interval = (0.0, 180.0)
    """Angles (degrees, anticlockwise from +x) the goals are drawn between: [0, 180] is the
    semicircle of the literature."""
    max_step: float = Field(default=0.1, gt=0.0, le=1.0)
    """Displacement (m) per step at action 1 on an axis."""
    bound: float = Field(default=2.0, gt=0.0, le=100.0)
    """The point is clamped to the square [-bound, bound]^2."""

    @model_validator(mode="after")
    def _arc(self) -> PointMassBackendSpec:
        _check_intervals(self, ("goal_arc",))
        if self.goal_radius >= self.bound:
            raise ValueError(f"'goal_radius' ({self.goal_radius:g}) must be < 'bound' ({self.bound:g}), or no goal is reachable")
        return self

    def describe(self) -> str:
        """One line for summaries (`taskforge validate`, `taskforge tasks`)."""
        low, high = self.goal_arc
        return f"point mass, goals on an arc of radius {self.goal_radius:g} m from {low:g} to {high:g} degrees"


BackendSpec = Annotated[
    MetaWorldBackendSpec | GymnasiumBackendSpec | XArm7BackendSpec | PointMassBackendSpec, Field(discriminator="type")
]
BACKEND_TYPES: tuple[str, ...] = tuple(
    typing.get_args(member.model_fields["type"].annotation)[0] for member in typing.get_args(typing.get_args(BackendSpec)[0])
)
"""Every backend `type`, in the union's order."""
