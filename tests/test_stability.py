"""A run survives what the simulator or the policy throws at it: non-finite actions and blown-up
simulations end the episode (truncated, counted), and a non-finite PPO loss is skipped, so no
NaN ever reaches the networks."""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pytest
import torch
import yaml

from taskforge.agents import PPOAgent, make_vector_env
from taskforge.envs import TaskEnv, load_task
from taskforge.run import RunDir, load_checkpoint
from taskforge.spec import AgentSpec, load_agent_spec
from taskforge.training import train
from tests.conftest import ROOT

XARM7 = ROOT / "tasks/xarm7/pick_place.yaml"
EXTREME = [  # the example of randomisation far beyond any real robot
    {"target": "body_mass", "op": "scale", "dist": "uniform", "low": 0.01, "high": 100.0},
    {"target": "dof_damping", "op": "scale", "dist": "loguniform", "low": 0.001, "high": 1000.0},
    {"target": "gravity", "op": "add", "dist": "normal", "mean": 0.0, "std": 20.0},
]


@pytest.mark.parametrize("task_file", [XARM7, ROOT / "tasks/metaworld/pick_place.yaml"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_action_ends_the_episode_as_truncated(task_file, bad):
    env = TaskEnv(load_task(task_file), task_file, stage="place")
    env.reset(seed=0)
    env.step(np.zeros(env.action_space.shape))
    obs, reward, terminated, truncated, info = env.step(np.full(env.action_space.shape, bad))
    assert truncated and not terminated and info["unstable"] and reward == 0.0
    assert np.isfinite(obs).all() and set(info["episode_reward_terms"]) == set(info["reward_terms"])
    obs, _ = env.reset(seed=1)  # and the next episode is an ordinary one
    obs, reward, terminated, truncated, info = env.step(np.zeros(env.action_space.shape))
    assert np.isfinite(obs).all() and np.isfinite(reward) and "unstable" not in info


def test_a_blown_up_simulation_ends_the_episode():
    """MuJoCo flags a bad acceleration (and resets the state behind the episode's back): the env
    ends the episode instead of going on from a state that never happened."""
    env = TaskEnv(load_task(XARM7), XARM7, stage="place")
    env.reset(seed=0)
    env.backend.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number += 1  # what mj_checkAcc does
    _, reward, _, truncated, info = env.step(np.zeros(env.action_space.shape))
    assert truncated and info["unstable"] and reward == 0.0
    env.reset(seed=1)  # mj_resetData clears the flag
    assert "unstable" not in env.step(np.zeros(env.action_space.shape))[4]


def test_training_under_extreme_randomisation_keeps_the_networks_finite(tmp_path):
    doc = yaml.safe_load(XARM7.read_text())
    doc["randomization"]["physics"] = EXTREME
    (tmp_path / "task.yaml").write_text(yaml.safe_dump(doc))
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(
        {"name": "tiny", "policy": {"hidden_sizes": [32, 32]}, "runtime": {"vector": "sync"},
         "ppo": {"num_envs": 2, "rollout_steps": 200, "num_minibatches": 2, "update_epochs": 2}}))
    (tmp_path / "cur.yaml").write_text(yaml.safe_dump(
        {"name": "extreme", "agent": "agent.yaml", "total_steps": 1200, "phases": [{"task": "task.yaml", "stages": ["reach"]}],
         "evaluation": {"every_steps": 1200, "episodes": 2}, "checkpoint": {"every_steps": 10_000}}))
    run = RunDir(train(tmp_path / "cur.yaml", run_dir=tmp_path / "run", progress=False))
    policy = load_checkpoint(run.final)["agent"]["policy"]
    assert all(torch.isfinite(v).all() for v in policy.values())
    metrics = run.read_metrics()
    assert all("unstable_episodes" in m and m["skipped_minibatches"] == 0 for m in metrics if "policy_loss" in m)


def test_a_non_finite_loss_is_skipped_not_applied():
    """One poisoned return (as a blown-up reward would make it): the minibatches holding it are
    skipped and counted; every weight stays finite."""
    task_file = ROOT / "tasks/metaworld/pick_place.yaml"
    task = load_task(task_file)
    base = load_agent_spec(ROOT / "agents/ppo.yaml")
    spec = AgentSpec.model_validate({
        **base.model_dump(), "ppo": {**base.ppo.model_dump(), "num_envs": 2, "rollout_steps": 64, "num_minibatches": 4, "update_epochs": 2},
        "runtime": {"vector": "sync"},
    })
    envs = make_vector_env([lambda: TaskEnv(task, task_file, stage="reach")] * 2, spec.runtime)
    probe = TaskEnv(task, task_file, stage="reach")
    agent = PPOAgent(spec, probe.observation_space, probe.action_space, 0, seed=0)
    agent.collect(envs, lambda *args: None)
    before = copy.deepcopy(agent.policy.state_dict())
    agent.buffer.returns[5, 1] = float("nan")
    metrics = agent.update()
    assert metrics["skipped_minibatches"] == spec.ppo.update_epochs  # one minibatch per epoch holds it
    after = agent.policy.state_dict()
    assert all(torch.isfinite(v).all() for v in after.values())
    assert any(not torch.equal(before[k], after[k]) for k in before)  # the clean minibatches were applied
    envs.close()


def test_mujoco_warnings_go_to_logging_not_to_a_file_in_the_working_directory(tmp_path):
    """A blown-up simulation (velocities of 1e20): MuJoCo's warning reaches taskforge's logger
    once, the env ends the episode, and no MUJOCO_LOG.TXT appears where the user ran from."""
    import subprocess
    import sys

    code = (
        "import numpy as np\n"
        "from taskforge.envs import TaskEnv, load_task\n"
        f"env = TaskEnv(load_task({str(XARM7)!r}), {str(XARM7)!r}, stage='reach')\n"
        "for seed in (0, 1):\n"
        "    env.reset(seed=seed)\n"
        "    env.backend.data.qvel[:] = 1e20\n"
        "    info = env.step(np.zeros(4))[4]\n"
        "    assert info['unstable'], info\n"
    )
    import os

    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this checkout's taskforge, run from elsewhere
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    lines = [line for line in run.stderr.splitlines() if line.startswith("MuJoCo: ")]
    assert len(lines) == 1 and "Nan, Inf or huge value" in lines[0]  # once per distinct message
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
