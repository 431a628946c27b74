"""Reward terms and success conditions on hand-set feature values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from taskforge.spec import StageSpec
from taskforge.terms import FEATURES, KERNELS, REWARD_TERMS, CompiledStage


def features(**overrides) -> dict:
    base = {name: (0.0 if info.size == 1 else np.zeros(info.size or 4)) for name, info in FEATURES.items()}
    base.update(overrides)
    return base


def term_value(name: str, f: dict, **params) -> float:
    term = REWARD_TERMS[name]
    return term.fn(f, term.params.model_validate(params))


@pytest.mark.parametrize("kernel", ["gaussian", "long_tail", "linear", "exponential"])
def test_kernels_are_one_at_zero_and_value_at_margin_at_margin(kernel):
    fn = KERNELS[kernel]
    assert fn(0.0, 0.2, 0.1) == pytest.approx(1.0)
    assert fn(0.2, 0.2, 0.1) == pytest.approx(0.1)
    assert fn(0.1, 0.2, 0.1) > fn(0.15, 0.2, 0.1)  # decreasing


def test_negative_kernel_is_minus_distance():
    assert KERNELS["negative"](0.3, 1.0, 0.1) == pytest.approx(-0.3)


def test_distance_terms_read_their_own_distance():
    f = features(tcp_to_object_distance=0.0, object_to_goal_distance=0.1, tcp_to_goal_distance=0.2)
    assert term_value("tcp_to_object", f) == pytest.approx(1.0)
    assert term_value("object_to_goal", f, margin=0.1) == pytest.approx(0.1)
    assert term_value("tcp_to_goal", f, kernel="linear", margin=0.4, value_at_margin=0.5) == pytest.approx(0.75)


def test_lift_saturates_and_ignores_sinking():
    assert term_value("lift", features(object_height=0.02), target_height=0.04) == pytest.approx(0.5)
    assert term_value("lift", features(object_height=0.5), target_height=0.04) == 1.0
    assert term_value("lift", features(object_height=-0.01), target_height=0.04) == 0.0


def test_indicator_and_passthrough_terms():
    assert term_value("grasp", features(object_grasped=1.0)) == 1.0
    assert term_value("native", features(native_reward=3.25)) == 3.25
    assert term_value("stage_success", features(stage_success=1.0)) == 1.0
    assert term_value("tcp_to_goal_progress", features(tcp_to_goal_progress=0.01)) == 0.01
    assert term_value("object_to_goal_progress", features(object_to_goal_progress=0.02)) == 0.02
    assert term_value("tcp_to_object_progress", features(tcp_to_object_progress=0.03)) == 0.03
    assert term_value("action_l2", features(action=np.array([1.0, -2.0, 0.0, 2.0]))) == pytest.approx(9.0)


def test_every_registered_term_has_docs_and_returns_a_float():
    for name, term in REWARD_TERMS.items():
        assert term.doc, name
        assert isinstance(term.fn(features(), term.params()), float), name


STAGE = StageSpec.model_validate(
    {
        "name": "pick",
        "rewards": [
            {"term": "tcp_to_object", "weight": 0.5, "params": {"margin": 0.1}},
            {"term": "lift", "weight": 2.0, "params": {"target_height": 0.04}},
            {"term": "tcp_to_object", "weight": 1.0, "params": {"kernel": "negative"}},
        ],
        "success": {"all": [{"feature": "object_grasped", "above": 0.5}, {"feature": "object_height", "above": 0.04, "below": 0.3}]},
    }
)


def test_stage_reward_is_weighted_sum_and_reports_each_term():
    stage = CompiledStage(STAGE)
    total, values = stage.reward(features(tcp_to_object_distance=0.1, object_height=0.02))
    assert values == {"tcp_to_object": pytest.approx(0.1), "lift": pytest.approx(0.5), "tcp_to_object#2": pytest.approx(-0.1)}
    assert total == pytest.approx(0.5 * 0.1 + 2.0 * 0.5 - 0.1)


def test_stage_success_flips_exactly_when_every_condition_holds():
    stage = CompiledStage(STAGE)
    assert not stage.success(features(object_grasped=0.0, object_height=0.1))
    assert not stage.success(features(object_grasped=1.0, object_height=0.04))  # strict inequality
    assert stage.success(features(object_grasped=1.0, object_height=0.0401))
    assert not stage.success(features(object_grasped=1.0, object_height=0.5))  # above `below`
    assert math.isfinite(stage.reward(features())[0])
