"""The sharded vector env behaves exactly like gymnasium's SyncVectorEnv with SAME_STEP autoreset."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from taskforge.agents.sharded import ShardedVectorEnv
from taskforge.envs import TaskEnv
from taskforge.spec import TaskSpec

TASK = TaskSpec.model_validate({
    "name": "pendulum",
    "backend": {"type": "gymnasium", "env": "Pendulum-v1"},
    "max_episode_steps": 7,
    "stages": [{"name": "swing", "rewards": [{"term": "native"}], "terminate_on_success": True,  # staggered ends
                "success": {"all": [{"feature": "native_reward", "above": -1.0}]}}],
    "randomization": {"observation_noise": {"per_step": {"dist": "normal", "std": 0.1}}},
})


def assert_infos_equal(a: dict, b: dict) -> None:
    """Every key, mask and value, recursively (object arrays element by element)."""
    assert list(a) == list(b)
    for key in a:
        x, y = a[key], b[key]
        if isinstance(x, dict):
            assert_infos_equal(x, y)
        elif x.dtype == object:
            assert y.dtype == object and len(x) == len(y)
            for u, v in zip(x, y):
                assert_infos_equal(u, v) if isinstance(u, dict) else np.testing.assert_array_equal(u, v)
        else:
            assert x.dtype == y.dtype, key
            np.testing.assert_array_equal(x, y)


def make_fns(n: int):
    return [partial(TaskEnv, TASK, "pendulum.yaml") for _ in range(n)]


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_matches_sync_vector_env_step_for_step(workers):
    sync = SyncVectorEnv(make_fns(5), autoreset_mode=AutoresetMode.SAME_STEP)
    sharded = ShardedVectorEnv(make_fns(5), num_shards=workers)
    assert sharded.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    a_obs, a_info = sync.reset(seed=11)
    b_obs, b_info = sharded.reset(seed=11)
    np.testing.assert_array_equal(a_obs, b_obs)
    assert_infos_equal(a_info, b_info)
    actions = np.random.default_rng(0).uniform(-1, 1, (20, 5, 1)).astype(np.float32)
    ended = []
    for action in actions:
        a, b = sync.step(action), sharded.step(action)
        for x, y in zip(a[:4], b[:4]):
            np.testing.assert_array_equal(x, y)
            assert x.dtype == y.dtype
        assert_infos_equal(a[4], b[4])
        ended.append(a[2] | a[3])
    ended = np.array(ended)
    assert ended.sum() >= 5  # episodes ended and were reset within the same step
    assert ((ended.sum(axis=1) > 0) & (ended.sum(axis=1) < 5)).any()  # some while others went on
    sharded.set_attr("next_episode", [{"replay": True}] * 5)
    assert sharded.get_attr("next_episode") == ({"replay": True},) * 5
    sync.close()
    sharded.close()


def test_worker_errors_reach_the_main_process():
    envs = ShardedVectorEnv(make_fns(2), num_shards=2)
    envs.reset(seed=0)
    with pytest.raises(RuntimeError, match="worker failed"):
        envs.get_attr("no_such_attribute")
    envs.close()
