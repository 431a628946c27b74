"""Schema of a task file: backend + scene, ordered stages, randomisation, goal splits.

Reward-term names, their parameters and feature names are *not* checked here: they live in
registries (`taskforge.terms`, `taskforge.backends`) that this package may not import. Those
registries check them in a second pass that reports errors with the same file + field path
(see `taskforge.envs.resolve`).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from taskforge.spec.backends import BackendSpec
from taskforge.spec.common import Distribution, StrictModel

Name = Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_\-]+$")]


# --- stages --------------------------------------------------------------------------------


class RewardTermSpec(StrictModel):
    """One weighted reward term: `weight * term(features, **params)`."""

    term: str
    weight: float = 1.0
    params: dict[str, Any] = Field(default_factory=dict)


class ConditionSpec(StrictModel):
    """`feature` strictly below and/or above a threshold."""

    feature: str
    below: float | None = None
    above: float | None = None

    @model_validator(mode="after")
    def _has_bound(self) -> ConditionSpec:
        if self.below is None and self.above is None:
            raise ValueError("a condition needs 'below' and/or 'above'")
        if self.below is not None and self.above is not None and self.above >= self.below:
            raise ValueError(f"'above' ({self.above}) must be < 'below' ({self.below})")
        return self


class SuccessSpec(StrictModel):
    """The stage succeeds when every condition in `all` holds (on `hold_steps` steps in a row)."""

    all: list[ConditionSpec] = Field(min_length=1)
    hold_steps: int = Field(default=1, ge=1, le=10_000)
    """Steps in a row the conditions must hold before the stage counts as succeeded. Why: with 1
    (Meta-World's convention), an object that only passes through the goal region succeeds, so a
    blind sweep scores well on a hidden goal and the first episode of an RL² trial is already
    near the ceiling; requiring the object to stay tells a search from knowing where the goal is."""


class GoalOverrideSpec(StrictModel):
    """How a stage reshapes the goal distribution of its backend.

    `height: object` puts the goal on the table at the object's resting height (a push stage);
    a number sets the goal height in metres; `keep` leaves it. `distance_scale` moves the goal
    towards the object's start in the horizontal plane (1 = unchanged, 0 = on the object),
    a classic way to make the early stages easy. `height_scale` does the same vertically: the
    goal's drawn height is moved towards `height` (0 = onto it, 1 = unchanged), so a curriculum
    can start with every goal on one plane and grow the plane back into the task's box.
    """

    height: Literal["keep", "object"] | float = "keep"
    distance_scale: float = Field(default=1.0, ge=0.0, le=1.0)
    height_scale: float = Field(default=0.0, ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _scale_needs_a_height(self) -> GoalOverrideSpec:
        if self.height == "keep" and self.height_scale != 0.0:
            raise ValueError("height_scale moves the goal's height towards 'height'; set height to a number or 'object' (got 'keep')")
        return self


class StageSpec(StrictModel):
    """One stage of the task: its reward terms, its success condition and what it changes."""

    name: Name
    rewards: list[RewardTermSpec] = Field(min_length=1)
    success: SuccessSpec
    max_episode_steps: int | None = Field(default=None, ge=1, le=100_000)
    terminate_on_success: bool = False
    goal: GoalOverrideSpec = GoalOverrideSpec()


# --- randomisation -------------------------------------------------------------------------

class PhysicsTermSpec(Distribution):
    """A draw applied to one kind of MuJoCo model parameter at every reset.

    `op: scale` multiplies the nominal value, `add` adds to it. `names` are regular
    expressions over the element names (bodies, geoms, joints or actuators); empty = all
    (for `object_size`: the backend's object geoms). `per_element: false` draws one value
    shared by every matched element.
    """

    target: str
    """A registered physics target (`taskforge.randomization.PHYSICS_TARGETS`): body_mass,
    geom_friction, dof_damping, joint_range, actuator_gain, gravity, object_size."""
    op: Literal["scale", "add"] = "scale"
    names: list[str] = Field(default_factory=list)
    per_element: bool = True


class NoiseSpec(StrictModel):
    """Additive noise (any `Distribution`, usually a zero-mean normal): `per_step` redrawn every step, `per_episode` once per
    episode (the correlated noise of *Learning Dexterity*)."""

    per_step: Distribution | None = None
    per_episode: Distribution | None = None


class LatencySpec(StrictModel):
    """The action applied is the one chosen `k` control steps ago, `k ~ U{min_steps..max_steps}`
    drawn at each reset."""

    min_steps: int = Field(default=0, ge=0, le=50)
    max_steps: int = Field(default=0, ge=0, le=50)

    @model_validator(mode="after")
    def _ordered(self) -> LatencySpec:
        if self.min_steps > self.max_steps:
            raise ValueError(f"'min_steps' ({self.min_steps}) must be <= 'max_steps' ({self.max_steps})")
        return self


class RandomizationSpec(StrictModel):
    physics: list[PhysicsTermSpec] = Field(default_factory=list)
    observation_noise: NoiseSpec = NoiseSpec()
    action_noise: NoiseSpec = NoiseSpec()
    action_latency: LatencySpec = LatencySpec()
    action_backlash: Distribution | None = None
    """Width of a backlash-like dead band on each action dimension (action units), drawn once per
    episode: the applied command only moves once the requested one has moved more than half the
    width away from it, as with play in a gearbox. Negative draws count as 0."""
    object_start: Literal["goal_set", "random"] = "goal_set"
    """Where the object starts. `goal_set`: where the goal entry puts it (ML1 draws one object
    placement with each goal, so the object's start is fixed per goal: an agent that sees the
    object can tell the goal from it). `random`: drawn afresh for each new task instance (each
    episode; under RL², each trial, whose episodes repeat it), uniformly over the backend's object
    region and independently of the goal, at least the backend's minimum distance from the goal
    horizontally. Needed wherever the goal is hidden and the object is observed (meta-RL on
    Meta-World), or the object names the goal."""


# --- goals ---------------------------------------------------------------------------------


class GoalSplitSpec(StrictModel):
    """One goal set. For Meta-World these are ML1's tasks (goal + object placement, at most 50);
    for Gymnasium envs, reset seeds."""

    count: int = Field(default=50, ge=1, le=1_000_000)


class TrainGoalSplitSpec(GoalSplitSpec):
    """The training goals: a fixed set, or a fresh draw per task instance."""

    draw: Literal["set", "fresh"] = "set"
    """`set`: each episode trains on one of the `count` entries (ML1's 50 tasks). `fresh`: each
    new task instance (each episode; under RL², each trial) draws its own goal and object start
    from the distribution the set is drawn from — Meta-World's unfrozen task vector, as the
    goal-observable Meta-World of TD-MPC2 trains; on the xArm7, a new entry in the train cells
    of the checkerboard. Why: trained on 50 fixed (object, goal) pairs, an agent can fit those
    pairs and miss held-out ones (MPC on ML1 push: 0.98 of its training pairs, 0.91 held-out).
    The test split stays a fixed set, so held-out success is measured as before; evaluating
    `split: train` under `fresh` draws fresh tasks too."""


class GoalsSpec(StrictModel):
    """The train and held-out test goal sets, and whether the goal is observed."""

    observable: bool = False
    """False hides the goal (meta-RL: the agent must infer it); True shows it in the observation."""
    seed: int = 0
    """Seed of the goal sets themselves: with the same seed, everyone gets the same goals."""
    train: TrainGoalSplitSpec = TrainGoalSplitSpec()
    test: GoalSplitSpec = GoalSplitSpec()


class ObservationSpec(StrictModel):
    """What the agent's observation holds beyond the backend's own."""

    relative_positions: bool = False
    """Append object − tool and goal − object (6 floats, from the backend's `tcp_pos`,
    `object_pos` and `goal_pos`; the goal part zeroed when the goal is hidden). The scripted
    teachers act on these differences; a policy given only absolute positions must learn the
    subtraction from 50 training configurations, and generalises poorly to held-out ones
    (xArm7 pick-place, behaviour cloning on 50 demos: 0.68 held-out without, 0.96 with)."""
    features: list[str] | None = None
    """Observe only these named features (e.g. `[tcp_pos, gripper_opening]`), concatenated in
    this order, instead of the backend's own observation. Why: Meta-World's 39 numbers hold a
    second object, quaternions and the previous frame; for a recurrent policy that must remember
    one place, each is input it has to learn to ignore. With the goal hidden, features that
    depend on the goal are refused (they would give it away)."""

    @field_validator("features")
    @classmethod
    def _features_unique(cls, features: list[str] | None) -> list[str] | None:
        if features is not None:
            if not features:
                raise ValueError("list at least one feature, or leave `features` out for the backend's own observation")
            dupes = sorted({f for f in features if features.count(f) > 1})
            if dupes:
                raise ValueError(f"features listed twice: {', '.join(dupes)}")
        return features


# --- the task file -------------------------------------------------------------------------


class TaskSpec(StrictModel):
    """A whole task file."""

    name: Name
    description: str = ""
    backend: BackendSpec
    max_episode_steps: int = Field(default=500, ge=1, le=100_000)
    stages: list[StageSpec] = Field(min_length=1)
    randomization: RandomizationSpec = RandomizationSpec()
    goals: GoalsSpec = GoalsSpec()
    observation: ObservationSpec = ObservationSpec()

    @field_validator("stages")
    @classmethod
    def _unique_stage_names(cls, stages: list[StageSpec]) -> list[StageSpec]:
        names = [s.name for s in stages]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"stage names must be unique; repeated: {', '.join(dupes)}")
        return stages

    def stage(self, name: str) -> StageSpec:
        for stage in self.stages:
            if stage.name == name:
                return stage
        raise KeyError(name)

    def episode_steps(self, stage: StageSpec) -> int:
        """The time limit of one of this task's stages: its own `max_episode_steps`, else the task's."""
        return stage.max_episode_steps or self.max_episode_steps

    @property
    def stage_names(self) -> list[str]:
        return [s.name for s in self.stages]
