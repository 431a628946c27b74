"""The reward-term registry: every term is a small pure function of the features dict.

Adding a term is one function plus its name here (and a YAML line that uses it): decorate it
with `@reward_term("name", reads=("feature", ...), params=SomeParams)`. `params` is a schema model, so a task file's
`params:` block is validated with the same one-line errors as the rest of the file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pydantic import Field

from taskforge.spec import StrictModel
from taskforge.terms.features import PROGRESS_FEATURES, Features
from taskforge.terms.kernels import KERNELS, KernelName


class NoParams(StrictModel):
    """For terms that take no parameters: any key given is an error."""


class DistanceParams(StrictModel):
    kernel: KernelName = "long_tail"
    margin: float = Field(default=0.1, gt=0.0, le=10.0)
    """Distance (m) at which the reward has fallen to `value_at_margin`."""
    value_at_margin: float = Field(default=0.1, gt=0.0, lt=1.0)


class LiftParams(StrictModel):
    target_height: float = Field(default=0.04, gt=0.0, le=1.0)
    """Height (m) above the resting height at which the lift reward saturates at 1."""


TermFn = Callable[[Features, StrictModel], float]


@dataclass(frozen=True)
class RewardTerm:
    name: str
    fn: TermFn
    params: type[StrictModel]
    reads: tuple[str, ...]
    """Features the term reads; a task is rejected if its backend does not provide them."""
    doc: str


REWARD_TERMS: dict[str, RewardTerm] = {}


def reward_term(
    name: str, reads: tuple[str, ...], params: type[StrictModel] = NoParams
) -> Callable[[TermFn], TermFn]:
    """Register `fn` under `name`; its docstring becomes the term's documentation."""

    def register(fn: TermFn) -> TermFn:
        if name in REWARD_TERMS:
            raise ValueError(f"reward term {name!r} registered twice")
        REWARD_TERMS[name] = RewardTerm(name, fn, params, reads, (fn.__doc__ or "").strip())
        return fn

    return register


def _distance_term(feature: str) -> TermFn:
    def term(f: Features, p: DistanceParams) -> float:
        return KERNELS[p.kernel](f[feature], p.margin, p.value_at_margin)

    term.__doc__ = f"kernel(`{feature}`): 1 at zero distance, `value_at_margin` at `margin`."
    return term


for _name, _feature in (
    ("tcp_to_object", "tcp_to_object_distance"),
    ("object_to_goal", "object_to_goal_distance"),
    ("tcp_to_goal", "tcp_to_goal_distance"),
):
    reward_term(_name, (_feature,), DistanceParams)(_distance_term(_feature))


def _progress_term(feature: str, distance: str) -> TermFn:
    def term(f: Features, p: NoParams) -> float:
        return f[feature]

    term.__doc__ = (f"`{feature}`: metres by which `{distance}` beat its episode record this step (>= 0). "
                    "Sums to start distance - closest distance over an episode: pays for a search that "
                    "passes the goal, not for hovering near where it might be (give it a weight per metre).")
    return term


for _feature, _distance in PROGRESS_FEATURES.items():
    reward_term(_feature, (_feature,))(_progress_term(_feature, _distance))


@reward_term("lift", ("object_height",), LiftParams)
def lift(f: Features, p: LiftParams) -> float:
    """`object_height / target_height`, clipped to [0, 1]: rewards lifting, saturating at the
    target so the agent is not paid to throw the object upwards."""
    return min(max(f["object_height"] / p.target_height, 0.0), 1.0)


@reward_term("grasp", ("object_grasped",))
def grasp(f: Features, p: NoParams) -> float:
    """1 while both finger pads press on the object (`object_grasped`)."""
    return f["object_grasped"]


@reward_term("action_l2", ("action",))
def action_l2(f: Features, p: NoParams) -> float:
    """Squared norm of the action; give it a negative weight to penalise large actions."""
    a = f["action"]
    return float(a @ a)


@reward_term("native", ("native_reward",))
def native(f: Features, p: NoParams) -> float:
    """The simulator suite's own reward (Meta-World's v2 shaped reward, 0..10)."""
    return f["native_reward"]


@reward_term("stage_success", ("stage_success",))
def stage_success(f: Features, p: NoParams) -> float:
    """1 on steps where the stage succeeds (its condition holds, on `success.hold_steps` steps in
    a row): a sparse bonus."""
    return f["stage_success"]
