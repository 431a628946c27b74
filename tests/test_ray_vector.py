"""`runtime.vector: ray` on a local Ray instance: the same trajectories as `sharded` for the same
seeds, and a run that survives a killed worker."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

ray = pytest.importorskip("ray")

from taskforge.agents.ray_shards import ray_vector_env  # noqa: E402
from taskforge.agents.sharded import ShardedVectorEnv  # noqa: E402
from taskforge.training import train  # noqa: E402
from tests.test_sharded_vector import TASK, assert_infos_equal, make_fns  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


def steps(envs, actions):
    return [envs.step(a) for a in actions]


def test_same_seeds_give_the_same_trajectories_as_the_sharded_vector_env():
    sharded = ShardedVectorEnv(make_fns(5), num_shards=3)
    on_ray = ray_vector_env(make_fns(5), workers=3, address=None, max_restarts=0)
    assert on_ray.shards == sharded.shards and on_ray.metadata == sharded.metadata
    a_obs, a_info = sharded.reset(seed=5)
    b_obs, b_info = on_ray.reset(seed=5)
    np.testing.assert_array_equal(a_obs, b_obs)
    assert_infos_equal(a_info, b_info)
    actions = np.random.default_rng(1).uniform(-1, 1, (20, 5, 1)).astype(np.float32)
    ended = 0
    for a, b in zip(steps(sharded, actions), steps(on_ray, actions)):
        for x, y in zip(a[:4], b[:4]):
            np.testing.assert_array_equal(x, y)
        assert_infos_equal(a[4], b[4])
        ended += int((a[2] | a[3]).sum())
    assert ended >= 5  # autoresets happened in the actors too
    on_ray.set_attr("next_episode", [{"replay": True}] * 5)
    assert on_ray.get_attr("next_episode") == ({"replay": True},) * 5
    sharded.close()
    on_ray.close()


def test_a_killed_worker_is_restarted_and_its_episodes_end_truncated_where_they_were():
    heard = []
    envs = ray_vector_env(make_fns(4), workers=2, address=None, max_restarts=2, on_restart=heard.append)
    envs.reset(seed=0)
    envs.set_attr("next_episode", [{"replay": True}] * 4)
    action = np.zeros((4, 1), dtype=np.float32)
    before, *_ = envs.step(action)
    ray.kill(envs._pipes[0].actor, no_restart=False)  # as if its process or node died mid-rollout
    for _ in range(100):  # the kill lands asynchronously: a step or two may still be answered
        obs, rewards, terminated, truncated, infos = envs.step(action)
        if heard:
            break
        before = obs

    (event,) = heard
    assert (event["kind"], event["envs"], event["during"], event["restart"]) == ("worker_restart", [0, 1], "step", 1)
    lost = slice(0, 2)
    assert truncated[lost].all() and not terminated[lost].any() and (rewards[lost] == 0).all()
    for i in range(2):  # the lost episodes end at the last observation the learner saw
        np.testing.assert_array_equal(infos["final_obs"][i], before[i])
    assert set(infos["final_info"]["episode_success"][:2]) <= {True, False}
    # the restarted envs got the attributes the trainer had set, and they step on
    assert envs.get_attr("next_episode")[:2] == ({"replay": True},) * 2
    assert envs.step(action)[0].shape == (4, *obs.shape[1:])
    envs.close()


def test_a_worker_that_keeps_dying_stops_the_run():
    envs = ray_vector_env(make_fns(2), workers=2, address=None, max_restarts=0)
    envs.reset(seed=0)
    ray.kill(envs._pipes[0].actor, no_restart=True)
    with pytest.raises(RuntimeError, match="died 1 times"):
        for _ in range(100):  # the kill lands asynchronously: a step or two may still be answered
            envs.step(np.zeros((2, 1), dtype=np.float32))
    envs.close()


def actor_pids() -> set[int]:
    found = subprocess.run(["pgrep", "-f", "ray::_ShardActor"], capture_output=True, text=True).stdout
    return {int(pid) for pid in found.split()}


def kill_a_worker_once(metrics: Path, after_updates: int) -> threading.Thread:
    """SIGKILL an env actor process Ray started from now on (the OOM killer's way), once the run
    has logged `after_updates` updates to `metrics`: mid-training, whatever the machine's speed."""
    old = actor_pids()

    def kill() -> None:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            new = actor_pids() - old
            if new and metrics.exists() and len(metrics.read_text().splitlines()) >= after_updates:
                os.kill(min(new), signal.SIGKILL)
                return
            time.sleep(0.05)

    thread = threading.Thread(target=kill, daemon=True)
    thread.start()
    return thread


def test_training_goes_on_after_a_worker_is_killed_and_logs_the_restart(tmp_path):
    (tmp_path / "task.yaml").write_text(yaml.safe_dump(TASK.model_dump(mode="json", exclude_unset=True)))
    agent = {"name": "on-ray", "ppo": {"num_envs": 4, "rollout_steps": 64, "num_minibatches": 2, "update_epochs": 1},
             "runtime": {"vector": "ray", "workers": 2, "ray_max_restarts": 2}}
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(agent))
    total = 30 * 4 * 64
    curriculum = {"name": "ray-run", "agent": "agent.yaml", "total_steps": total, "phases": [{"task": "task.yaml"}],
                  "evaluation": {"every_steps": total, "episodes": 2}, "checkpoint": {"every_steps": total}}
    (tmp_path / "curriculum.yaml").write_text(yaml.safe_dump(curriculum))
    killer = kill_a_worker_once(tmp_path / "run" / "metrics.jsonl", after_updates=5)
    run = train(tmp_path / "curriculum.yaml", run_dir=tmp_path / "run", progress=False)
    killer.join(timeout=1)
    events = [json.loads(line) for line in (run / "events.jsonl").read_text().splitlines()]
    restarts = [e for e in events if e["kind"] == "worker_restart"]
    assert len(restarts) == 1 and restarts[0]["envs"] == [0, 1], events
    metrics = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert metrics[-1]["step"] == total and "eval_success_rate" in metrics[-1]
    assert 5 * 4 * 64 <= restarts[0]["step"] < total  # it happened mid-run, and the run went on
