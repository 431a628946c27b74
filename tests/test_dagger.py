"""DAgger and the hand-over to PPO: expert labels on the student's own states, exploration noise
sized from the cloning error, critic-only updates, frozen observation statistics, the step budget,
and a short warm-started run that keeps its success once PPO takes over."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
import yaml
from metaworld.policies import ENV_POLICY_MAP

from taskforge.agents import PPOAgent, make_vector_env
from taskforge.agents.bc import fit_exploration_std
from taskforge.demos.labels import EXPERT_ACTION, ExpertLabels
from taskforge.envs import TaskEnv, load_task
from taskforge.run import read_jsonl
from taskforge.training import train
from taskforge.training.dagger import DaggerRound, student_rollout
from tests.conftest import PICK_PLACE, TASKS
from tests.test_agents_ppo import SMALL_PPO, agent_spec, pendulum_envs

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def noiseless_pick_place(tmp_path):
    """pick-place without observation noise: the agent's observation is then exactly what
    Meta-World's own policy reads, so a label can be recomputed from the observation alone."""
    path = tmp_path / "pick_place_clean.yaml"
    path.write_text(yaml.safe_dump({"base": str(PICK_PLACE), "name": "clean", "randomization": {"observation_noise": {"per_step": None, "per_episode": None}}}))
    return path


def test_dagger_labels_are_the_scripted_action_at_the_states_the_student_visits(tmp_path):
    task_file = noiseless_pick_place(tmp_path)
    task = load_task(task_file)
    spec = agent_spec(policy={"hidden_sizes": [32, 32], "init_log_std": -0.5}, ppo=SMALL_PPO, runtime={"vector": "sync"})
    probe = TaskEnv(task, task_file)
    agent = PPOAgent(spec, probe.observation_space, probe.action_space, seed=3)
    obs_dim = probe.observation_space.shape[0]
    probe.close()
    fns = [lambda: ExpertLabels(TaskEnv(task, task_file, stage="place"), "place") for _ in range(2)]
    envs = make_vector_env(fns, spec.runtime)
    try:
        batch = student_rollout(agent, envs, steps=120, seed=5)
    finally:
        envs.close()
    assert obs_dim == 39 + 6 and batch.observations.shape == (120, obs_dim) and batch.expert_actions.shape == (120, 4)
    expert = ENV_POLICY_MAP["pick-place-v3"]()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        # Meta-World's policy parses its own 39 floats, not the relative positions taskforge appends
        recomputed = np.stack([np.clip(expert.get_action(o[:39].astype(np.float64)), -1, 1) for o in batch.observations])
    np.testing.assert_allclose(batch.expert_actions, recomputed, atol=1e-5)
    # the states are the student's: an untrained policy does not follow the expert's path to the puck
    hand, puck = batch.observations[:, 0:3], batch.observations[:, 4:7]
    assert np.linalg.norm(hand - puck, axis=1).min() > 0.03


def test_a_round_reports_success_per_sub_task():
    empty = np.zeros((0, 1))
    batch = DaggerRound(empty, empty, np.zeros(0, bool), [True, True, False, True, False, False, False],
                        ["a", "a", "b", "b", "c", "c", "c"])
    assert batch.success_by_task() == {"a": 1.0, "b": 0.5, "c": 0.0} and batch.success_rate == pytest.approx(3 / 7)


def test_a_dagger_round_on_a_task_set_records_each_episodes_sub_task(tmp_path):
    """MT10 with 3-step episodes (the bookkeeping, not the behaviour, is under test): every
    finished episode comes back with its sub-task, and they spread over the ten tasks."""
    spec = yaml.safe_load((TASKS / "metaworld/mt10.yaml").read_text())
    spec["max_episode_steps"] = 3
    task_file = tmp_path / "mt10.yaml"
    task_file.write_text(yaml.safe_dump(spec))
    task = load_task(task_file)
    agent_cfg = agent_spec(policy={"hidden_sizes": [16]}, ppo=SMALL_PPO, runtime={"vector": "sync"})
    probe = TaskEnv(task, task_file)
    agent = PPOAgent(agent_cfg, probe.observation_space, probe.action_space, seed=0)
    names = set(probe.backend.task_names)
    probe.close()
    envs = make_vector_env([lambda: ExpertLabels(TaskEnv(task, task_file, stage="solve"), "solve") for _ in range(2)], agent_cfg.runtime)
    try:
        batch = student_rollout(agent, envs, steps=120, seed=1)
    finally:
        envs.close()
    assert len(batch.episode_tasks) == len(batch.episode_successes) == 40  # 2 envs x 60 steps / 3
    assert set(batch.episode_tasks) <= names and len(set(batch.episode_tasks)) >= 6
    assert set(batch.success_by_task()) == set(batch.episode_tasks)


def test_expert_labels_wrapper_labels_the_returned_state_not_the_previous_one():
    env = ExpertLabels(TaskEnv(load_task(PICK_PLACE), PICK_PLACE, stage="reach"), "reach")
    obs, info = env.reset(seed=0)
    twin = ExpertLabels(TaskEnv(load_task(PICK_PLACE), PICK_PLACE, stage="reach"), "reach").policy
    for _ in range(20):
        obs, _, _, _, info = env.step(np.array([1.0, 0.0, 0.0, -1.0], dtype=np.float32))  # drive away
        np.testing.assert_array_equal(info[EXPERT_ACTION], np.clip(twin(env.task_env), -1, 1))
    env.close()


def test_exploration_std_is_the_cloning_error_scaled_and_clipped():
    spec = agent_spec(policy={"hidden_sizes": [16]}, ppo=SMALL_PPO)
    envs = pendulum_envs(spec)
    agent = PPOAgent(spec, envs.single_observation_space, envs.single_action_space, seed=0)
    envs.close()
    obs = np.random.default_rng(0).normal(size=(200, 3)).astype(np.float32)
    with torch.no_grad():
        mean = agent.policy.actions.to_env(agent.policy.distribution(agent.obs_normalizer(obs, update=False)[None], None,
                                                                       torch.zeros((1, 200), dtype=torch.bool))[0].mean[0])
    actions = (mean + 0.3).numpy()  # every prediction 0.3 off
    std = fit_exploration_std(agent, obs, actions, scale=2.0, low=0.05, high=1.0)
    np.testing.assert_allclose(std, [0.6], rtol=1e-4)
    np.testing.assert_allclose(agent.policy.actor_logstd.exp().detach().numpy(), [0.6], rtol=1e-4)
    assert fit_exploration_std(agent, obs, actions, scale=10.0, low=0.05, high=1.0)[0] == pytest.approx(1.0)
    assert fit_exploration_std(agent, obs, mean.numpy(), scale=1.0, low=0.05, high=1.0)[0] == pytest.approx(0.05)


def test_critic_warm_up_leaves_the_actor_alone_then_hands_over():
    spec = agent_spec(policy={"hidden_sizes": [16]}, ppo=SMALL_PPO)
    envs = pendulum_envs(spec)
    agent = PPOAgent(spec, envs.single_observation_space, envs.single_action_space, seed=0)
    agent.warm_up_critic(2)
    agent.freeze_observation_statistics()
    stats = agent.obs_normalizer.rms.state_dict()

    def snapshot(prefix: str) -> list[torch.Tensor]:
        return [p.detach().clone() for n, p in agent.policy.named_parameters() if n.startswith(prefix)]

    try:
        for k in range(3):
            actor, critic = snapshot("actor"), snapshot("critic")
            agent.collect(envs)
            metrics = agent.update()
            actor_moved = any(not torch.equal(a, b) for a, b in zip(actor, snapshot("actor")))
            critic_moved = any(not torch.equal(a, b) for a, b in zip(critic, snapshot("critic")))
            assert critic_moved and actor_moved == (k == 2) and metrics["actor_trained"] == float(k == 2), k
    finally:
        envs.close()
    # rollouts never touched the frozen observation statistics, and both settings survive a checkpoint
    assert all(torch.equal(v, agent.obs_normalizer.rms.state_dict()[k]) for k, v in stats.items())
    restored = PPOAgent(spec, envs.single_observation_space, envs.single_action_space, seed=1)
    restored.load_state_dict(agent.state_dict())
    assert restored.observation_stats_frozen and restored.critic_warmup_until == 2


def warm_reach(folder, agent: dict, total_steps: int, critic_warmup_steps: int):
    """A curriculum on pick-place's `reach`, warm-started from 12 scripted episodes and one DAgger
    round of 1,200 steps, evaluated on 10 held-out goals every 2,400 steps."""
    (folder / "agent.yaml").write_text(yaml.safe_dump(agent))
    doc = {"name": "warm-reach", "agent": "agent.yaml", "total_steps": total_steps,
           "phases": [{"task": str(PICK_PLACE), "stages": ["reach"]}],
           "evaluation": {"every_steps": 2_400, "episodes": 10, "split": "test", "stop_on_success": True},
           "checkpoint": {"every_steps": 100_000},
           "warm_start": {"generate_episodes": 12, "stage": "reach", "bc_epochs": 30,
                          "dagger": {"rounds": 1, "steps_per_round": 1_200, "epochs": 10},
                          "fine_tune": {"critic_warmup_steps": critic_warmup_steps}}}
    path = folder / "c.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_a_warm_started_run_keeps_its_success_when_ppo_takes_over(tmp_path):
    """The pick-place `reach` stage, warm-started from 12 scripted episodes and one DAgger round,
    then 6 PPO updates (2 critic-only): the evaluation right after pretraining (logged at the
    expert's step count) is high, and fine-tuning does not lose it. Before the hand-over was
    fixed (std 1, moving observation statistics) success fell within a few updates."""
    agent = {"name": "small", "policy": {"hidden_sizes": [64, 64]},
             "ppo": {"num_envs": 4, "rollout_steps": 300, "num_minibatches": 4, "update_epochs": 4},
             "runtime": {"vector": "sync", "update_threads": 1}}
    cur = warm_reach(tmp_path, agent, total_steps=12_000, critic_warmup_steps=2_400)
    run = train(cur, run_dir=tmp_path / "run", progress=False)
    records = read_jsonl(run / "metrics.jsonl")
    first = records[0]
    assert first["expert_steps"] == 12 * 150 + 1_200 and first["step"] == first["expert_steps"]  # counted in the budget
    evals = [r["eval_success_rate"] for r in records if "eval_success_rate" in r]
    assert first["eval_success_rate"] >= 0.8, evals
    assert len(evals) >= 4 and min(evals[1:]) >= first["eval_success_rate"] - 0.1, evals
    assert [r["actor_trained"] for r in records if "actor_trained" in r][:3] == [0.0, 0.0, 1.0]

    # DAgger's labels are kept, so a resumed run reinstalls the BC term on demos + labels, and
    # neither pretrains again nor restarts the critic warm-up
    with np.load(run / "dagger.npz") as labelled:
        assert labelled["observations"].shape == (1_200, 39 + 6)  # + relative positions and labelled["actions"].shape == (1_200, 4)
    end = records[-1]["step"]
    train(cur, run_dir=run, steps=end + 1_200, resume=True, progress=False)
    resumed = [r for r in read_jsonl(run / "metrics.jsonl") if r["step"] > end]
    assert resumed and all(r["actor_trained"] == 1.0 and r["bc_weight"] > 0 for r in resumed if "actor_trained" in r)
    assert sum("expert_steps" in r for r in read_jsonl(run / "metrics.jsonl")) == 1


def test_a_recurrent_student_is_warm_started_on_whole_episodes(tmp_path):
    """The same warm start with an LSTM policy: DAgger's rollouts carry its state and come back
    env by env, so each labelled episode lies contiguous (150-step `reach` episodes start every
    150 rows), cloning on whole episodes makes it reach the puck right after pretraining, and a
    resumed run reinstalls the BC term from the saved episodes."""
    agent = {"name": "small-lstm", "policy": {"type": "lstm", "recurrent_size": 64, "hidden_sizes": [64]},
             "ppo": {"num_envs": 4, "rollout_steps": 300, "num_minibatches": 4, "update_epochs": 2, "bptt_length": 50},
             "runtime": {"vector": "sync", "update_threads": 1}}
    cur = warm_reach(tmp_path, agent, total_steps=6_000, critic_warmup_steps=1_200)
    run = train(cur, run_dir=tmp_path / "run", progress=False)
    first = read_jsonl(run / "metrics.jsonl")[0]
    assert first["eval_success_rate"] >= 0.7 and first["bc_action_mse"] < first["bc_action_mse_before"], first
    with np.load(run / "dagger.npz") as labelled:
        starts = labelled["episode_starts"]
    assert len(starts) == 1_200 and np.flatnonzero(starts).tolist() == [0, 150, 300, 450, 600, 750, 900, 1050]
    end = read_jsonl(run / "metrics.jsonl")[-1]["step"]
    train(cur, run_dir=run, steps=end + 1_200, resume=True, progress=False)
    resumed = [r for r in read_jsonl(run / "metrics.jsonl") if r["step"] > end and "bc_weight" in r]
    assert resumed and all(r["bc_weight"] > 0 and np.isfinite(r["bc_loss"]) for r in resumed)
