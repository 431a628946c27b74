"""Scripted policies that produce demonstrations, chosen per backend and per stage.

Two kinds:

* **Native**: a simulator suite's own scripted policy for its full task. For Meta-World, the
  policy of `metaworld.policies.ENV_POLICY_MAP[env]` (per sub-task for MT10). Those read
  Meta-World's goal-*observable* 39-float observation, so they are fed
  `backend.native_observation()` (true goal, no noise), never the agent's observation (goal
  possibly hidden, noise added). Their action is the agent's action (the env passes actions
  straight to Meta-World).
* **Waypoint planner** (`WaypointPlanner`): a closed-loop, stateless planner on the shared
  features (`tcp_pos`, `object_pos`, `goal_pos`, `gripper_opening`, `object_height`) that emits
  4-D Cartesian actions `(dx, dy, dz, grip)`. Every step it re-decides where the tool should go
  from the current features, so it copes with the task's randomisation (object and goal
  placement, masses, friction, latency, action noise) without any state to get out of sync.
  Behaviours: `reach_object`, `reach_goal`, `push`, `pick`, `place`.

`scripted_policy(env, stage)` picks one: the native policy for a task's *last* stage (by
convention the full task; earlier stages are easier versions of it) when the backend has one,
otherwise the planner with a behaviour inferred from the stage's success condition.

Conventions (Meta-World's, checked in `SawyerXYZEnv.step`: the gripper actuators get
`(a[3], -a[3])` and its pick-place policy closes with `+1`; xArm7's Cartesian mode is the same):
`dx, dy, dz` in `[-1, 1]` are the backend's Cartesian step (Meta-World: 1 cm per unit per step;
xArm7: `control.max_step_m`); `grip` is **-1 open, +1 close**.

Which backends the planner drives is read from their record (`taskforge.backends.BACKENDS`,
`cartesian_actions`), with the default numbers; a backend's own scripted policy is an entry of
`_NATIVE` below. Other numbers or another policy, at run time:

    from taskforge.demos import PlannerConfig, register_backend
    register_backend("mybackend", planner=PlannerConfig(gain=5.0, hover=0.1))

A backend whose action is a 4-D Cartesian delta + gripper reuses the planner with its own
numbers (`planner=`); `native=` takes a factory `(env, stage) -> ScriptedPolicy | None` for the
backend's own scripted policies. A backend with another action space (e.g. xArm7's joint mode)
needs a `native` factory (e.g. mink IK on the planner's Cartesian waypoints); `scripted_policy`
refuses it otherwise.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np

from taskforge.backends import BACKENDS
from taskforge.spec import SpecError, expected_one_of

if TYPE_CHECKING:
    from taskforge.envs import TaskEnv

Behaviour = Literal["reach_object", "reach_goal", "push", "pick", "place"]
BEHAVIOURS: tuple[Behaviour, ...] = ("reach_object", "reach_goal", "push", "pick", "place")
Source = Literal["auto", "native", "planner"]


class ScriptedPolicy(Protocol):
    """Acts on a `TaskEnv` from its true state (features or the backend's raw observation)."""

    name: str

    def reset(self, env: TaskEnv) -> None:
        """Called after every `env.reset()`."""

    def __call__(self, env: TaskEnv) -> np.ndarray:
        """The next action, in the env's action space."""


# ------------------------------------------------------------------------------ the planner


@dataclass(frozen=True)
class PlannerConfig:
    """A backend's numbers for `WaypointPlanner` (defaults: Meta-World's Sawyer)."""

    gain: float = 10.0
    """Action per metre of position error (Meta-World moves the hand 1 cm per unit action, so 10
    reaches full speed 10 cm away, as Meta-World's own policies)."""
    grip_open: float = -1.0
    grip_close: float = 1.0
    hover: float = 0.08
    """Height (m) above the object at which the tool travels before descending onto it."""
    xy_tolerance: float = 0.012
    """Horizontal error (m) under which the tool is 'above' the object and may close on it."""
    funnel: float = 0.03
    """Width (m) of the funnel the tool descends in onto the object: its target height falls
    linearly from `hover` at `xy_tolerance + funnel` of horizontal error to the grasp height at
    `xy_tolerance`. A funnel rather than a step ('hover until above, then descend') because a
    student cloning the planner averages the two sides of a step into hovering (measured on
    xArm7: a BC + DAgger student stuck 5-8 cm above the cube, 0.12 held-out success)."""
    grasp_height: float = 0.0
    """Tool height (m) relative to the object's centre when closing the fingers."""
    closed_below: float = 0.75
    """`gripper_opening` under which the fingers count as closed on the object."""
    lift: float = 0.10
    """Height (m) above the object's resting height to lift it to (`pick`)."""
    push_contact: float = 0.035
    """Distance (m) from the object's centre to the tool's centre when the closed fingers touch
    it (Meta-World's puck: measured 0.031-0.035 from every side)."""
    push_height: float = -0.01
    """Tool height (m) relative to the object's centre while pushing: low, so the push does not
    tip the object over (a tipped puck rolls away)."""
    push_lead: float = 0.02
    """How far (m) ahead of the contact point the tool aims while pushing: sets the push speed
    (an action of `gain * push_lead`), slow enough that the object does not slide past the goal."""
    push_lateral_tolerance: float = 0.025
    """Sideways error (m) behind the object beyond which the tool goes back around it."""
    push_done: float = 0.01
    """Object-to-goal distance (m) at which a push stops."""
    release_height: float = 0.02
    """`place` opens the fingers at the goal only when the goal is this close (m) above the
    object's resting height (a goal on the table); goals in the air are held."""


class WaypointPlanner:
    """Cartesian waypoints from the shared features; see the module doc."""

    def __init__(self, behaviour: Behaviour, config: PlannerConfig = PlannerConfig()):
        if behaviour not in BEHAVIOURS:
            raise ValueError(f"unknown behaviour {behaviour!r}; expected one of {', '.join(BEHAVIOURS)}")
        self.behaviour = behaviour
        self.config = config
        self.name = f"planner:{behaviour}"

    def reset(self, env: TaskEnv) -> None:
        pass  # stateless: every step decides from the current features

    def __call__(self, env: TaskEnv) -> np.ndarray:
        f = env.features()
        tcp = np.asarray(f["tcp_pos"], dtype=float)
        obj = np.asarray(f.get("object_pos", tcp), dtype=float)
        goal = np.asarray(f.get("goal_pos", tcp), dtype=float)
        target, grip = getattr(self, f"_{self.behaviour}")(f, tcp, obj, goal)
        return self._action(tcp, target, grip)

    def _action(self, tcp: np.ndarray, target: np.ndarray, grip: float) -> np.ndarray:
        delta = self.config.gain * (target - tcp)
        largest = np.abs(delta).max()
        if largest > 1.0:  # scale, not clip per axis, so the tool moves straight at the target
            delta /= largest
        return np.append(delta, grip).astype(np.float32)

    # -- behaviours: each returns (tool target, grip command) --------------------------------

    def _reach_goal(self, f, tcp, obj, goal):
        return goal, self.config.grip_open

    def _reach_object(self, f, tcp, obj, goal):
        c = self.config
        if _xy_dist(tcp, obj) > c.xy_tolerance:  # from above, so the fingers do not knock it away
            return obj + [0.0, 0.0, max(c.hover / 2, tcp[2] - obj[2])], c.grip_open
        return obj, c.grip_open

    def _pick(self, f, tcp, obj, goal, carry_to: np.ndarray | None = None):
        c = self.config
        rest_z = obj[2] - float(f.get("object_height", 0.0))
        lifted = obj[2] - rest_z > 0.01
        holding = float(f["gripper_opening"]) < c.closed_below and np.linalg.norm(tcp - obj) < 0.04
        if holding and (lifted or _xy_dist(tcp, obj) < c.xy_tolerance):
            if carry_to is None:
                carry_to = np.array([obj[0], obj[1], rest_z + c.lift])
            return tcp + (carry_to - obj), c.grip_close  # move the object, not the tool, to the target
        xy = _xy_dist(tcp, obj)
        if xy > c.xy_tolerance or tcp[2] - (obj[2] + c.grasp_height) > 0.008:
            # pre-grasp, fingers open: down the funnel above the object (see `funnel`)
            drop = min(1.0, max(0.0, (xy - c.xy_tolerance) / c.funnel))
            return obj + [0.0, 0.0, c.grasp_height + drop * (c.hover - c.grasp_height)], c.grip_open
        return obj + [0.0, 0.0, c.grasp_height], c.grip_close  # close; wait until closed

    def _place(self, f, tcp, obj, goal):
        c = self.config
        rest_z = obj[2] - float(f.get("object_height", 0.0))
        on_table = goal[2] - rest_z < c.release_height
        if on_table and np.linalg.norm(obj - goal) < 0.02:
            return tcp + [0.0, 0.0, 0.05], c.grip_open  # release and back off upwards
        # carry high enough to clear the table, then over the goal, then down to it
        if _xy_dist(obj, goal) > 0.03:
            height = max(goal[2], rest_z + c.lift / 2)
            return self._pick(f, tcp, obj, goal, carry_to=np.array([goal[0], goal[1], height]))
        return self._pick(f, tcp, obj, goal, carry_to=goal)

    def _push(self, f, tcp, obj, goal):
        c = self.config
        to_goal = goal[:2] - obj[:2]
        dist = float(np.linalg.norm(to_goal))
        if dist < c.push_done:
            return tcp, c.grip_close  # there: stay still, so the object is not pushed past it
        d = to_goal / dist
        rel = tcp[:2] - obj[:2]
        along = float(rel @ d)  # negative: behind the object
        side = np.array([-d[1], d[0]])
        lateral = float(rel @ side)
        low = obj[2] + c.push_height
        # near the goal the direction to it swings with every millimetre, so sideways errors are
        # tolerated there rather than starting over
        tolerance = c.push_lateral_tolerance if dist > 2 * c.push_contact else c.push_contact
        if along < -(c.push_contact - 0.01) and abs(lateral) < tolerance and tcp[2] < low + 0.015:
            # behind it, low: stay on the line through the object and the goal, a little ahead
            # of the contact point; the lead shrinks near the goal so the object does not slide past
            ahead = min(dist, c.push_lead)
            return np.array([*(obj[:2] - d * (c.push_contact - ahead)), low]), c.grip_close
        start = np.array([*(obj[:2] - d * (c.push_contact + 0.025)), low])  # clear of the object
        if _xy_dist(tcp, start) > 2 * c.xy_tolerance:  # loose: the object may still be sliding
            if tcp[2] < obj[2] + c.hover / 2 and _xy_dist(tcp, obj) < c.push_contact + 0.04:
                return np.array([tcp[0], tcp[1], obj[2] + c.hover]), c.grip_close  # up, out of its way
            return start + [0.0, 0.0, c.hover], c.grip_close  # over the spot behind the object
        return start, c.grip_close  # down behind it


def act_in_box(policy: ScriptedPolicy, env: TaskEnv) -> np.ndarray:
    """The scripted action clipped to the env's action box: what the agent could have chosen, so
    what demonstrations record and DAgger labels."""
    space = env.action_space
    return np.clip(np.asarray(policy(env), dtype=np.float32), space.low, space.high)


def _xy_dist(a: np.ndarray, b: np.ndarray) -> float:
    return math.hypot(float(a[0] - b[0]), float(a[1] - b[1]))


def infer_behaviour(env: TaskEnv, stage: str) -> Behaviour:
    """What a stage asks for, read from its success condition (and its goal override).

    grasp/lift conditions -> `pick`; object-to-goal -> `push` when the stage puts the goal on the
    table (`goal.height: object`), else `place`; tool-to-object -> `reach_object`; tool-to-goal
    -> `reach_goal`.
    """
    spec = env.stages[stage].spec
    features = {c.feature for c in spec.success.all}
    if features & {"object_grasped", "object_height"}:
        return "pick"
    if "object_to_goal_distance" in features:
        return "push" if spec.goal.height == "object" else "place"
    if "tcp_to_object_distance" in features:
        return "reach_object"
    if "tcp_to_goal_distance" in features:
        return "reach_goal"
    raise SpecError.single(
        env.file, "stage", f"cannot tell what stage '{stage}' asks for from its success condition "
        f"({', '.join(sorted(features))}); the planner knows conditions on object_grasped, object_height, "
        "object_to_goal_distance, tcp_to_object_distance and tcp_to_goal_distance",
    )


# ------------------------------------------------------------------------ native policies


AIM_FINGERTIPS = frozenset({"reach-v3", "reach-wall-v3"})
"""Meta-World envs whose scripted policy is given the goal raised by the hand-to-fingertips
offset. Why: these envs score success at the fingertips' midpoint (`tcp_center`, within 5 cm of
the goal), but their policy steers the hand body, 4.5 cm above it, onto the goal. Left alone the
policy ends every episode 4.5 cm from the goal (measured on reach-v3: 19 of 20 held-out goals at
0.045 m), a 5 mm margin that a cloned student misses about a third of the time. Aimed at the
fingertips, the same policy ends on the goal (ARCHITECTURE.md, warm start)."""


@dataclass(frozen=True)
class HeldReading:
    """How a Meta-World policy that carries an object is told the object is held: while the
    fingers are closed around it (`_read_as_held`), the object is read `below` metres under the
    hand, inside the band where the policy's "held" tests pass, and with `centred` also right
    under the hand in xy."""

    below: float
    centred: bool


READ_AS_HELD: dict[str, HeldReading] = {
    "peg-insert-side-v3": HeldReading(below=0.02, centred=False),
    "push-v3": HeldReading(below=0.03, centred=True),
    "pick-place-v3": HeldReading(below=0.03, centred=True),
}
"""Meta-World envs whose scripted policy reads a gripped object as held. Why: these policies
decide from positions alone whether the object is held (peg-insert-side: the peg <= 2.5 cm below
the hand; push: the puck < 4 cm below and < 2 cm off in xy; pick-place: < 2 cm off in xy), and a
real grasp sits on or beyond those edges: a gripped peg hangs 2.5-2.8 cm below the hand, and a
puck gripped off-centre or high (as a student grips it) reads as not held. The policy then
answers "descend onto it" or "go above it" to an object already in its fingers, pressing it into
the table or lifting it away: peg-insert-side stalls on 7 of 40 train goals as shipped (5 of
40 test goals), and off its own path, where DAgger asks it for labels, push and pick-place fail
too. Read as held, the same policies score 1.00 on their own path, and with Gaussian noise on
every action (std 0.3 / 0.6, 30 train goals) push 0.90 / 0.40 -> 1.00 / 0.97, pick-place
0.87 / 0.57 -> 0.97 / 0.53, peg-insert-side 0.87 / 0.63 -> 0.97 / 0.70 (`benchmarks/teachers.py`).
Meta-World's code still decides every action."""

HELD_OPENING = 0.6
"""Gripper opening (`obs[3]`, 1 open) below which the fingers count as closed on the object:
~0.97 while they approach it, 0.3-0.5 holding it."""
HELD_REACH = (0.04, 0.07)
"""How near the hand the object must be to count as gripped: in xy, and below it (m)."""


def _read_as_held(obs: np.ndarray, reading: HeldReading) -> None:
    """Move the object in `obs` (in place) to where the policy reads it as held, while the
    fingers are closed around it. Meta-World's layout: hand `obs[0:3]`, opening `obs[3]`, the
    first object `obs[4:7]`."""
    hand, opening, obj = obs[0:3], obs[3], obs[4:7]
    near_xy, near_below = HELD_REACH
    if opening < HELD_OPENING and np.linalg.norm(hand[:2] - obj[:2]) <= near_xy and hand[2] - obj[2] < near_below:
        if reading.centred:
            obs[4:6] = hand[:2]
        obs[6] = max(obj[2], hand[2] - reading.below)


class MetaWorldPolicy:
    """Meta-World's own scripted policy for each env of the task (one, or the ten of MT10), fed
    Meta-World's goal-observable observation; the env of the current episode picks which. For
    the envs of `AIM_FINGERTIPS` the goal it reads is moved so it brings the scored point there;
    for those of `READ_AS_HELD` a gripped object reads as held."""

    def __init__(self, env_names: list[str]):
        from metaworld.policies import ENV_POLICY_MAP

        self.policies = {name: ENV_POLICY_MAP[name]() for name in env_names}
        names = sorted({type(p).__name__ for p in self.policies.values()})
        self.name = "metaworld:" + (names[0] if len(names) == 1 else f"{len(names)} policies")

    def reset(self, env: TaskEnv) -> None:
        pass

    def __call__(self, env: TaskEnv) -> np.ndarray:
        backend = env.backend
        obs = backend.native_observation()
        if backend.active_task in AIM_FINGERTIPS:
            obs[backend.goal_slice] += obs[:3] - backend.features()["tcp_pos"]  # obs[:3]: the hand body
        if backend.active_task in READ_AS_HELD:
            _read_as_held(obs, READ_AS_HELD[backend.active_task])
        with warnings.catch_warnings():  # `move()` warns whenever its gain saturates the action
            warnings.simplefilter("ignore", UserWarning)
            return np.asarray(self.policies[backend.active_task].get_action(obs), dtype=np.float32)


def _metaworld_native(env: TaskEnv, stage: str) -> ScriptedPolicy | None:
    from metaworld.policies import ENV_POLICY_MAP

    names = list(env.backend.task_names)
    if not all(name in ENV_POLICY_MAP for name in names):
        return None
    return MetaWorldPolicy(names)


NativeFactory = Callable[["TaskEnv", str], "ScriptedPolicy | None"]


_NATIVE: dict[str, NativeFactory] = {"metaworld": _metaworld_native}
"""A backend's own scripted policies, by backend type."""
_PLANNERS: dict[str, PlannerConfig] = {}
"""Planner numbers other than the defaults, by backend type (`register_backend`). Meta-World's
numbers work on the xArm7 in `control.mode: cartesian` as they are (measured: 20/20 episodes on
each stage of tasks/xarm7/pick_place.yaml)."""


def register_backend(backend_type: str, native: NativeFactory | None = None, planner: PlannerConfig | None = None) -> None:
    """Make `scripted_policy` work for a backend type, or change its numbers (see the module doc)."""
    if native is not None:
        _NATIVE[backend_type] = native
    if planner is not None:
        _PLANNERS[backend_type] = planner


def _planner_config(backend_type: str) -> PlannerConfig | None:
    if backend_type in _PLANNERS:
        return _PLANNERS[backend_type]
    info = BACKENDS.get(backend_type)
    return PlannerConfig() if info is not None and info.cartesian_actions else None


def scripted_policy(env: TaskEnv, stage: str | None = None, source: Source = "auto") -> ScriptedPolicy:
    """The scripted policy for one stage of `env`'s task (default: the env's current stage).

    `source="auto"`: the backend's native policy on the task's last stage (the full task), the
    waypoint planner elsewhere (and on the last stage when there is no native policy);
    `"native"` or `"planner"` forces one. Raises `SpecError` when none fits.
    """
    stage = stage or env.stage
    if stage not in env.stages:
        raise SpecError.single(env.file, "stage", f"no stage '{stage}'; {expected_one_of(stage, env.stages)}")
    backend_type = env.task.backend.type
    native, planner = _NATIVE.get(backend_type), _planner_config(backend_type)
    last = stage == env.task.stages[-1].name
    if source in ("auto", "native") and native is not None and (last or source == "native"):
        policy = native(env, stage)
        if policy is not None:
            return policy
    if source == "native":
        raise SpecError.single(env.file, "backend", f"the {backend_type} backend has no scripted policy for this task")
    if planner is None or env.action_space.shape != (4,):
        raise SpecError.single(
            env.file, "backend", f"no scripted policy for the {backend_type} backend; demonstrations need a "
            "backend with 4-D Cartesian actions or a registered policy (taskforge/demos/policies.py)",
        )
    return WaypointPlanner(infer_behaviour(env, stage), planner)
