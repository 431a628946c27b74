"""Warm start from demonstrations: behaviour cloning on Meta-World's reach stage, the DAPG-style
regulariser in PPO, the curriculum's `warm_start` section, and training with it end to end."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import torch
import yaml
from gymnasium.spaces import Box

from taskforge.agents import PPOAgent
from taskforge.agents.bc import pretrain, returns_to_go, scaled_rewards
from taskforge.cli import main
from taskforge.demos import Demos, generate, save
from taskforge.envs import load_curriculum, load_task
from taskforge.rollouts import evaluate
from taskforge.run import read_jsonl
from taskforge.training import train
from tests.conftest import PICK_PLACE
from tests.test_agents_ppo import SMALL_PPO, agent_spec, make_agent, pendulum_envs
from tests.test_training import AGENT, TASK

pytestmark = pytest.mark.usefixtures("one_torch_thread")

# Meta-World's 39 floats + the relative positions pick_place.yaml appends
OBS, ACT = Box(-np.inf, np.inf, (39 + 6,), np.float32), Box(-1.0, 1.0, (4,), np.float32)


def small_agent(seed: int = 0, **policy) -> PPOAgent:
    spec = agent_spec(policy={"hidden_sizes": [64, 64], **policy}, ppo=SMALL_PPO, runtime={"vector": "sync", "update_threads": 1})
    return PPOAgent(spec, OBS, ACT, seed=seed)


# ------------------------------------------------------------------------ behaviour cloning


def test_bc_on_reach_demos_lowers_action_error_and_raises_success():
    """16 scripted reach episodes (2400 steps), 40 epochs of BC: on 6 held-out goals the policy
    goes from never reaching the puck to reaching it (measured: 0/6 -> 6/6, and 10/10 on 10
    goals; action MSE 0.28 -> 0.002). With 8 episodes it is 8/10: a few demos are not enough."""
    task = load_task(PICK_PLACE)
    demos = generate(PICK_PLACE, "reach", episodes=16, seed=0)
    assert demos.num_episodes == 16
    agent = small_agent()
    before = evaluate(agent, task, PICK_PLACE, "reach", "test", trials=6, seed=500)
    rewards = scaled_rewards(agent, demos.rewards, demos.episode_starts, demos.terminated)
    targets = returns_to_go(rewards, demos.episode_starts, demos.truncated, agent.spec.ppo.gamma)
    metrics = pretrain(agent, demos.observations, demos.actions, targets, epochs=40, batch_size=128, learning_rate=1e-3)
    after = evaluate(agent, task, PICK_PLACE, "reach", "test", trials=6, seed=500)
    assert metrics["bc_action_mse"] < 0.2 * metrics["bc_action_mse_before"], metrics
    assert metrics["bc_value_mse"] < 0.2 * metrics["bc_value_mse_before"], metrics
    assert before.success_rate <= 1 / 6 and after.success_rate >= 5 / 6, (before.success_rate, after.success_rate)
    # the normaliser has seen the demos, and the exploration std was left alone (MSE on the mean)
    assert float(agent.obs_normalizer.rms.count) >= demos.num_steps
    assert torch.equal(agent.policy.actor_logstd, small_agent().policy.actor_logstd)


def test_returns_to_go_bootstrap_truncated_episodes_only():
    rewards = np.array([1.0, 1.0, 1.0, 2.0, 2.0])
    starts = np.array([True, False, False, True, False])
    truncated = np.array([False, False, True, False, False])  # episode 1 hit the time limit, 2 terminated
    out = returns_to_go(rewards, starts, truncated, gamma=0.5)
    np.testing.assert_allclose(out, [1 + 0.5 * (1 + 0.5 * 2.0), 1 + 0.5 * 2.0, 2.0, 2 + 0.5 * 2, 2.0])


def test_a_recurrent_policy_is_cloned_on_whole_episodes_and_needs_their_starts():
    """An LSTM that must remember: the action of every step of an episode is the sign of its first
    observation, which the later observations no longer show. Cloned as whole episodes from a
    fresh state it learns that; without the episode starts it is refused, not cloned wrongly."""
    agent = small_agent(type="lstm")
    rng = np.random.default_rng(0)
    episodes, length = 40, 6
    first = rng.choice([-1.0, 1.0], size=episodes)
    obs = np.zeros((episodes * length, OBS.shape[0]), dtype=np.float32)
    obs[::length, 0] = first  # only the first step shows the cue
    obs[:, 1] = np.tile(np.arange(length), episodes)  # the step within the episode
    actions = np.repeat(first, length)[:, None] * np.full((1, 4), 0.5, dtype=np.float32)
    starts = np.tile([True] + [False] * (length - 1), episodes)
    with pytest.raises(ValueError, match="episode_starts"):
        pretrain(agent, obs, actions)
    with pytest.raises(ValueError, match="episode_starts"):
        agent.set_demo_regularizer(obs, actions, 0.1, 0.9)
    metrics = pretrain(agent, obs, actions, epochs=150, batch_size=60, learning_rate=3e-3, episode_starts=starts)
    # an MLP cannot do better than 0.25 on the later steps (it must guess the sign); the LSTM can
    assert metrics["bc_action_mse"] < 0.05 < metrics["bc_action_mse_before"], metrics
    agent.set_demo_regularizer(obs, actions, 0.1, 0.9, episode_starts=starts)
    rows = agent.demo_regularizer.rows
    assert rows.width == episodes and rows.index.shape == (length, episodes) and rows.mask.all()


# -------------------------------------------------------------------------- the regulariser


def test_bc_regularizer_decays_as_configured_and_pulls_towards_the_demos():
    spec = agent_spec(policy={"hidden_sizes": [32, 32]}, ppo={**SMALL_PPO, "learning_rate": 1e-2, "update_epochs": 4})
    rng = np.random.default_rng(0)
    demo_obs = rng.normal(size=(64, 3)).astype(np.float32)
    demo_act = np.full((64, 1), 1.5, dtype=np.float32)  # Pendulum's torque box is [-2, 2]

    def nll_after(weight: float) -> tuple[float, list[dict]]:
        envs = pendulum_envs(spec)
        agent = make_agent(spec, envs, seed=1)
        agent.set_demo_regularizer(demo_obs, demo_act, weight=weight, decay=0.5)
        metrics = []
        for _ in range(3):
            agent.collect(envs)
            metrics.append(agent.update())
        envs.close()
        with torch.no_grad():
            obs = agent.obs_normalizer(demo_obs, update=False)
            dist, _ = agent.policy.distribution(obs[None], None, torch.zeros((1, 64), dtype=torch.bool))
            return float(-dist.log_prob(torch.as_tensor(demo_act)[None]).sum(-1).mean()), metrics

    strong, metrics = nll_after(20.0)
    assert [m["bc_weight"] for m in metrics] == [20.0, 10.0, 5.0]  # weight * decay**k at update k
    assert all(np.isfinite(m["bc_loss"]) for m in metrics)
    off, metrics_off = nll_after(0.0)
    assert [m["bc_weight"] for m in metrics_off] == [0.0, 0.0, 0.0]
    assert strong < off - 0.2, (strong, off)


def test_updates_without_demos_carry_no_bc_metrics():
    spec = agent_spec(policy={"hidden_sizes": [32, 32]}, ppo=SMALL_PPO)
    envs = pendulum_envs(spec)
    agent = make_agent(spec, envs)
    agent.collect(envs)
    assert not {"bc_loss", "bc_weight"} & set(agent.update())
    envs.close()


# ---------------------------------------------------------------------- curriculum section


def pendulum_demos(episodes: int = 4, length: int = 25, stage: str = "easy") -> Demos:
    rng = np.random.default_rng(0)
    n = episodes * length
    starts = np.zeros(n, dtype=bool)
    starts[::length] = True
    ends = np.roll(starts, -1)
    return Demos(
        observations=rng.normal(size=(n, 3)).astype(np.float32),
        actions=rng.uniform(-2, 2, size=(n, 1)).astype(np.float32),
        rewards=rng.normal(size=n).astype(np.float32),
        successes=np.zeros(n, dtype=bool),
        episode_starts=starts,
        terminated=np.zeros(n, dtype=bool),
        truncated=ends,
        episode_lengths=np.full(episodes, length),
        episode_success=np.ones(episodes, dtype=bool),
        goal_indices=np.arange(episodes),
        metadata={"stage": stage, "task": "pendulum-two-stage"},
    )


def write_files(folder, warm_start: dict, agent: dict = AGENT, **overrides):
    (folder / "task.yaml").write_text(yaml.safe_dump(TASK))
    (folder / "agent.yaml").write_text(yaml.safe_dump(agent))
    doc = {
        "name": "warm",
        "agent": "agent.yaml",
        "seed": 2,
        "total_steps": 600,
        "phases": [{"task": "task.yaml"}],
        "promotion": {"threshold": 0.9, "window": 4},
        "evaluation": {"every_steps": 10_000, "episodes": 1},
        "checkpoint": {"every_steps": 200},
        "warm_start": warm_start,
        **overrides,
    }
    path = folder / "curriculum.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_a_curriculum_with_warm_start_validates(tmp_path, capsys):
    save(pendulum_demos(), tmp_path / "demos" / "d.npz")
    cur = write_files(tmp_path, {"demos": "demos/d.npz", "regularizer": {"weight": 0.2, "decay": 0.9}})
    resolved = load_curriculum(cur)
    assert resolved.demos_file == tmp_path / "demos" / "d.npz"
    assert resolved.spec.warm_start.bc_epochs == 50 and resolved.spec.warm_start.regularizer.decay == 0.9
    assert main(["validate", str(cur)]) == 0
    assert "warm start from" in capsys.readouterr().out


@pytest.mark.parametrize(
    "warm_start, field, fragment",
    [
        ({"demos": "d.npz", "generate_episodes": 5}, "warm_start", "exactly one of 'demos'"),
        ({}, "warm_start", "exactly one of 'demos'"),
        ({"demos": "missing.npz"}, "warm_start.demos", "file not found"),
        ({"generate_episodes": 0}, "warm_start.generate_episodes", "greater than or equal to 1"),
        ({"generate_episodes": 5, "stage": "hardest"}, "warm_start.stage", "no stage 'hardest'"),
        ({"generate_episodes": 5, "phase": 3}, "warm_start.phase", "no phase 3"),
        ({"generate_episodes": 5, "phase": -1}, "warm_start.phase", "counting from 0, or 'all'; got -1"),
        ({"generate_episodes": 5, "phase": "every"}, "warm_start.phase", "'all'"),
        ({"generate_episodes": 5, "regularizer": {"wieght": 1.0}}, "warm_start.regularizer.wieght", "did you mean 'weight'"),
        ({"generate_episodes": 5, "regularizer": {"decay": 1.5}}, "warm_start.regularizer.decay", "less than or equal to 1"),
        ({"generate_episode": 5}, "warm_start.generate_episode", "did you mean 'generate_episodes'"),
    ],
)
def test_bad_warm_start_sections_are_one_line_errors(warm_start, field, fragment, tmp_path, capsys):
    cur = write_files(tmp_path, warm_start)
    assert main(["validate", str(cur)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and f"curriculum.yaml: {field}: " in lines[0] and fragment in lines[0], lines


def test_warm_start_with_an_rl2_agent_is_refused(tmp_path, capsys):
    rl2 = copy.deepcopy(AGENT)
    rl2.update(algo="rl2", rl2={"trial_episodes": 2}, policy={"type": "gru", "hidden_sizes": [32]})
    cur = write_files(tmp_path, {"generate_episodes": 2}, agent=rl2)
    assert main(["validate", str(cur)]) == 2
    err = capsys.readouterr().err
    assert "warm_start: a warm start clones single episodes" in err and "Traceback" not in err


# ----------------------------------------------------------------------------- training


def test_training_pretrains_once_and_the_regularizer_survives_resume(tmp_path):
    save(pendulum_demos(), tmp_path / "d.npz")
    cur = write_files(tmp_path, {"demos": "d.npz", "bc_epochs": 3, "regularizer": {"weight": 0.5, "decay": 0.5}})
    run = tmp_path / "run"
    train(cur, run_dir=run, steps=400, progress=False)
    train(cur, run_dir=run, steps=600, resume=True, progress=False)
    metrics = read_jsonl(run / "metrics.jsonl")
    # the 100 demo steps count in the budget: the run's clock starts there
    assert metrics[0]["step"] == 100 and "bc_action_mse" in metrics[0] and "bc_value_mse" in metrics[0]
    assert sum("bc_action_mse" in m for m in metrics) == 1  # not pretrained again on resume
    updates = [m for m in metrics if "bc_weight" in m]
    assert [m["step"] for m in updates] == [300, 500, 700]
    assert [m["bc_weight"] for m in updates] == [0.5, 0.25, 0.125]  # decay continues across the resume
    # promotions are on the run's clock (demo steps included), where the plot draws them
    promotions = [e for e in read_jsonl(run / "events.jsonl") if e["kind"] == "promote"]
    assert promotions and all(e["step"] in {m["step"] for m in metrics} for e in promotions)
    assert all(e["step"] == e["curriculum_step"] + 100 for e in promotions)


def test_training_with_demos_of_another_stage_is_refused(tmp_path, capsys):
    save(pendulum_demos(stage="easy"), tmp_path / "d.npz")
    cur = write_files(tmp_path, {"demos": "d.npz", "stage": "hard"})
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "warm_start.stage: 'hard', but" in err
    assert not (tmp_path / "run").exists()  # nothing written before the inputs are known to be good


@pytest.mark.parametrize("stage,obs_size,fragment", [
    ("hard", 3, "warm_start.stage: 'hard', but"),
    ("easy", 5, "warm_start.demos: demo observations have 5 floats; the policy reads 3"),
])
def test_validate_checks_the_demos_file_as_train_does(stage, obs_size, fragment, tmp_path, capsys):
    """`validate` said `ok` to a curriculum whose demos `train` then refused."""
    demos = pendulum_demos(stage="easy")
    demos.observations = np.zeros((demos.num_steps, obs_size), dtype=np.float32)
    save(demos, tmp_path / "d.npz")
    cur = write_files(tmp_path, {"demos": "d.npz", "stage": stage})
    assert main(["validate", str(cur)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and fragment in err
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run"), "--no-progress"]) == 2
    assert fragment in capsys.readouterr().err


def test_training_generates_metaworld_demos_and_keeps_them_for_resume(tmp_path):
    agent = {"name": "tiny", "policy": {"hidden_sizes": [32, 32]},
             "ppo": {"num_envs": 1, "rollout_steps": 50, "num_minibatches": 1, "update_epochs": 1},
             "runtime": {"vector": "sync", "update_threads": 1}}
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(agent))
    doc = {"name": "mw-warm", "agent": "agent.yaml", "total_steps": 50,
           "phases": [{"task": str(PICK_PLACE), "stages": ["reach", "push"]}],
           "evaluation": {"every_steps": 10_000, "episodes": 1},
           "warm_start": {"generate_episodes": 2, "stage": "reach", "bc_epochs": 2}}
    cur = tmp_path / "c.yaml"
    cur.write_text(yaml.safe_dump(doc))
    run = train(cur, run_dir=tmp_path / "run", progress=False)
    kept = run / "demos.npz"
    with np.load(kept) as data:
        meta = json.loads(str(data["metadata"]))
        assert meta["stage"] == "reach" and meta["episodes_run"] == 2 and data["observations"].shape[1] == 39 + 6
    first = read_jsonl(run / "metrics.jsonl")[0]
    assert meta["steps_run"] == 2 * 150  # both reach episodes ran to the stage's time limit
    assert first["step"] == meta["steps_run"] and first["bc_demo_episodes"] == meta["episodes_kept"]


def test_warm_start_and_evaluation_over_every_phase(tmp_path, capsys):
    """`warm_start.phase: all` records the demos over every phase's task (episodes split evenly) and
    `evaluation.tasks: all` evaluates every phase's task: one row per task in the log and at the end."""
    agent = {"name": "tiny", "policy": {"hidden_sizes": [32, 32]},
             "ppo": {"num_envs": 2, "rollout_steps": 50, "num_minibatches": 1, "update_epochs": 1},
             "runtime": {"vector": "sync", "update_threads": 1}}
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(agent))
    push = PICK_PLACE.parent / "push.yaml"
    doc = {"name": "two-tasks", "agent": "agent.yaml", "total_steps": 100,
           "phases": [{"task": str(PICK_PLACE), "stages": ["reach"]}, {"task": str(push), "stages": ["reach"]}],
           "evaluation": {"every_steps": 10_000, "episodes": 1, "tasks": "all", "stop_on_success": True},
           "warm_start": {"generate_episodes": 3, "phase": "all", "bc_epochs": 2, "dagger": {"rounds": 1, "steps_per_round": 100}}}
    cur = tmp_path / "c.yaml"
    cur.write_text(yaml.safe_dump(doc))
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run"), "--no-progress"]) == 0
    out = capsys.readouterr()
    assert "scripted success on the train goals: metaworld-pick-place" in out.err

    with np.load(tmp_path / "run" / "demos.npz") as data:
        meta = json.loads(str(data["metadata"]))
    assert [(p["task"], p["episodes_run"]) for p in meta["parts"]] == [("metaworld-pick-place", 2), ("metaworld-push", 1)]
    assert meta["stage"] == "reach" and meta["steps_run"] == 3 * 150
    first = read_jsonl(tmp_path / "run" / "metrics.jsonl")[0]
    assert first["step"] == 3 * 150 + 100  # demos and DAgger's student steps (both phases' envs)
    assert {"eval/metaworld-pick-place", "eval/metaworld-push", "demo_success/metaworld-push"} <= set(first)
    final = json.loads((tmp_path / "run" / "final_eval.json").read_text())
    assert [(row["task"], row["stage"], row["episodes"]) for row in final["tasks"]] == [
        ("metaworld-pick-place", "reach", 1), ("metaworld-push", "reach", 1)]
    assert final["episodes"] == 2 and "2 tasks" in out.out and "  metaworld-push: " in out.out
