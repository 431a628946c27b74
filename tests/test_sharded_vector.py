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
    "stages": [{"name": "swing", "rewards": [{"term": "native"}],
                "success": {"all": [{"feature": "native_reward", "above": -0.5}]}}],
    "randomization": {"observation_noise": {"per_step": {"dist": "normal", "std": 0.1}}},
})


def make_fns(n: int):
    return [partial(TaskEnv, TASK, "pendulum.yaml") for _ in range(n)]


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_matches_sync_vector_env_step_for_step(workers):
    sync = SyncVectorEnv(make_fns(5), autoreset_mode=AutoresetMode.SAME_STEP)
    sharded = ShardedVectorEnv(make_fns(5), num_workers=workers)
    assert sharded.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    a_obs, a_info = sync.reset(seed=11)
    b_obs, b_info = sharded.reset(seed=11)
    np.testing.assert_array_equal(a_obs, b_obs)
    actions = np.random.default_rng(0).uniform(-1, 1, (20, 5, 1)).astype(np.float32)
    ended = 0
    for action in actions:
        a, b = sync.step(action), sharded.step(action)
        for x, y in zip(a[:4], b[:4]):
            np.testing.assert_array_equal(x, y)
        a_info, b_info = a[4], b[4]
        assert a_info.keys() == b_info.keys()
        if "final_obs" in a_info:
            ended += 1
            np.testing.assert_array_equal(a_info["_final_obs"], b_info["_final_obs"])
            for i in np.flatnonzero(a_info["_final_obs"]):
                np.testing.assert_array_equal(a_info["final_obs"][i], b_info["final_obs"][i])
            np.testing.assert_array_equal(a_info["final_info"]["episode_success"], b_info["final_info"]["episode_success"])
        np.testing.assert_array_equal(a_info["stage"], b_info["stage"])
    assert ended >= 2  # episodes of 7 steps ended and were reset within the same step
    sharded.set_attr("next_episode", [{"replay": True}] * 5)
    assert sharded.get_attr("next_episode") == ({"replay": True},) * 5
    sync.close()
    sharded.close()


def test_worker_errors_reach_the_main_process():
    envs = ShardedVectorEnv(make_fns(2), num_workers=2)
    envs.reset(seed=0)
    with pytest.raises(RuntimeError, match="worker failed"):
        envs.get_attr("no_such_attribute")
    envs.close()
