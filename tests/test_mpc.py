"""`algo: mpc`: PETS's ensemble learns dynamics and reward, each planner finds a known optimum,
and the agent trains through the curriculum (goal-observable point mass), evaluates, resumes."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
import torch
import yaml
from gymnasium.spaces import Box

import benchmarks.common
from benchmarks import model_based, mpc_data_probe, mpc_prior_probe, mpc_probe, mpc_push_probe
from taskforge.agents import MPCAgent, make_vector_env
from taskforge.agents.dynamics import DynamicsEnsemble
from taskforge.agents.mpc import TransitionBuffer
from taskforge.agents.planners import plan
from taskforge.agents.policy_value import PolicyValue
from taskforge.agents.value import TerminalValue
from taskforge.agents.weights import WeightsMismatch
from taskforge.cli import main
from taskforge.demos import concatenate, generate, record, save
from taskforge.envs import TaskEnv, load_task
from taskforge.run import load_checkpoint, load_run, read_jsonl
from taskforge.spec import AgentSpec, load_agent_spec
from taskforge.spec.agent import MPCSpec
from taskforge.training import train
from tests.conftest import ROOT

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_the_ensemble_learns_dynamics_and_reward_and_knows_its_noise():
    """s' = s + 0.1 a + noise(0.01), r = -|s'|: after fitting, the mean prediction's error is near
    the noise floor and the predicted std of the next state is about the noise's."""
    rng = np.random.default_rng(0)
    s = rng.uniform(-1, 1, (4000, 2)).astype(np.float32)
    a = rng.uniform(-1, 1, (4000, 2)).astype(np.float32)
    s2 = s + 0.1 * a + rng.normal(0, 0.01, s.shape).astype(np.float32)
    r = -np.linalg.norm(s2, axis=1).astype(np.float32)
    spec = MPCSpec(ensemble_size=3, hidden_sizes=[64, 64], particles=3)
    model = DynamicsEnsemble(2, 2, spec, torch.Generator().manual_seed(0))
    inputs = torch.as_tensor(np.concatenate([s, a], axis=1))
    targets = torch.as_tensor(np.concatenate([s2 - s, r[:, None]], axis=1))
    model.fit_normalization(inputs, targets)
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    gen = torch.Generator().manual_seed(1)
    for _ in range(1500):
        idx = torch.randint(4000, (3, 256), generator=gen)
        loss = model.loss(inputs[idx], targets[idx])
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    x = inputs[None, :500].expand(3, -1, -1)
    with torch.no_grad():
        next_obs, reward = model.mean_prediction(x[..., :2], x[..., 2:])
        _, logvar, _ = model((x - model.in_mean) / model.in_std)
    assert ((next_obs - torch.as_tensor(s2[:500])) ** 2).mean().sqrt() < 0.02  # noise 0.01
    assert ((reward - torch.as_tensor(r[:500])) ** 2).mean().sqrt() < 0.05
    predicted_std = (torch.exp(0.5 * logvar) * model.out_std[:2]).mean()
    assert 0.005 < predicted_std < 0.02, predicted_std


def _fit_with_constant_columns(nll_beta: float) -> float:
    """A hand-like position that moves by 0.02 a plus half its last step (the last position is in
    the observation) plus noise 0.002, beside 8 columns that never change and 8 that never change
    within a row's step: what Meta-World's observation looks like to the model. The mean
    prediction's error on the position after 2,000 steps of the ensemble's loss."""
    rng = np.random.default_rng(0)
    n = 4000
    pos = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
    last = pos + rng.uniform(-0.05, 0.05, (n, 2)).astype(np.float32)
    act = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
    new = pos + 0.02 * act + 0.5 * (pos - last) + rng.normal(0, 0.002, pos.shape).astype(np.float32)
    zeros, still = np.zeros((n, 8), np.float32), np.repeat(rng.uniform(-1, 1, (n, 1)).astype(np.float32), 8, axis=1)
    obs, next_obs = np.c_[pos, last, zeros, still], np.c_[new, pos, zeros, still]
    inputs = torch.as_tensor(np.c_[obs, act])
    targets = torch.as_tensor(np.c_[next_obs - obs, np.zeros((n, 1), np.float32)])
    model = DynamicsEnsemble(20, 2, MPCSpec(ensemble_size=3, hidden_sizes=[64, 64], particles=3, nll_beta=nll_beta),
                             torch.Generator().manual_seed(0))
    model.fit_normalization(inputs, targets)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(1)
    for _ in range(2000):
        idx = torch.randint(n, (3, 256), generator=gen)
        model.fit_batch(optimizer, inputs[idx], targets[idx])
    with torch.no_grad():
        predicted, _ = model.mean_prediction(inputs[None, :1000, :20].expand(3, -1, -1), inputs[None, :1000, 20:].expand(3, -1, -1))
    return (predicted.mean(0)[:, :2] - torch.as_tensor(new[:1000])).norm(dim=1).mean().item()


def test_beta_nll_learns_the_motion_that_the_plain_likelihood_leaves_as_noise():
    """PETS's likelihood lets the never-changing columns (log-variance at the floor) take the
    shared layers and leaves the moving position "noise"; β-NLL (0.5) fits it to the noise floor
    (~0.0025) in the same steps. On Meta-World pick-place this was the difference between a
    model no better than "no motion" and one that planned 0.70 of held-out goals."""
    plain, beta = _fit_with_constant_columns(0.0), _fit_with_constant_columns(0.5)
    assert beta < 0.004, beta
    assert plain > 3 * beta, (plain, beta)  # the failure β-NLL is for: this data must show it


def test_nll_beta_one_gives_the_mean_the_squared_errors_gradient():
    """With β = 1 the gradient on a predicted mean does not depend on its predicted variance; with
    β = 0 (PETS) it is scaled by one over it."""
    grads = {}
    for beta in (0.0, 1.0):
        model = DynamicsEnsemble(2, 1, MPCSpec(ensemble_size=1, hidden_sizes=[8], particles=1, nll_beta=beta), torch.Generator().manual_seed(0))
        mean = torch.zeros((1, 1, 2), requires_grad=True)
        logvar = torch.tensor([[[0.0, -4.0]]])
        model._change = lambda x, mean=mean, logvar=logvar: (mean, logvar)  # the network's outputs, fixed
        model.loss(torch.zeros((1, 1, 3)), torch.tensor([[[1.0, 1.0, 0.0]]])).backward()
        grads[beta] = mean.grad[0, 0]
    assert grads[1.0][0] == pytest.approx(grads[1.0][1])
    assert grads[0.0][1] / grads[0.0][0] == pytest.approx(np.exp(4.0), rel=1e-4)


def test_the_terminal_value_learns_the_discounted_sum_of_rewards():
    """A state that stays put and pays r = s every step is worth s / (1 - discount) = 10 s: TD(0)
    with a target network gets there from transitions alone, to within a few percent."""
    gen = torch.Generator().manual_seed(0)
    value = TerminalValue(1, [32, 32], discount=0.9, tau=0.05, generator=gen)
    s = torch.rand((2000, 1), generator=gen)
    optimizer = torch.optim.Adam(value.net.parameters(), lr=3e-3)
    metrics = value.fit(s, s[:, 0], s, s.mean(0), s.std(0), optimizer, updates=3000, batch=256, generator=gen)
    probe = torch.linspace(0.05, 0.95, 10)[:, None]
    with torch.no_grad():
        np.testing.assert_allclose(value(probe).numpy(), 10 * probe[:, 0].numpy(), atol=0.3)
    assert 4.0 < metrics["value_mean"] < 6.0  # 10 x the mean state, 0.5


def test_the_policy_value_learns_a_policy_better_than_the_data_and_its_q():
    """TD3+BC on a one-step problem: state s in [0, 1] stays put, the reward -|a - (2s - 1)| pays
    for matching an action to the state, and the data's actions are uniform. Its policy learns to
    match (the data's own actions do not: their mean is 0 everywhere), and `Q(s, pi(s))`, the
    planner's score, is worth more than what the data's behaviour earns."""
    gen = torch.Generator().manual_seed(0)
    value = PolicyValue(1, 1, [64, 64], discount=0.5, tau=0.05, generator=gen)
    s = torch.rand((4000, 1), generator=gen)
    a = torch.rand((4000, 1), generator=gen) * 2 - 1
    best = 2 * s - 1
    reward = -(a - best).abs()[:, 0]
    metrics = value.fit(s, a, reward, s, s.mean(0), s.std(0), value.optimizers(), updates=3000, batch=256, generator=gen)
    with torch.no_grad():
        chosen = value.policy(s)
        # measured: the policy's error 0.04 (the data's 0.67), its value -0.39 against the data's -1.33
        assert (chosen - best).abs().mean() < 0.3
        assert value(s).mean() > 2 * reward.mean()  # the data's behaviour is worth reward / (1 - 0.5)
    assert np.isfinite(metrics["value_loss"]) and {"policy_loss", "value_mean"} <= set(metrics)


@pytest.mark.parametrize("kind", ["v", "q"])
def test_value_bound_pulls_an_overestimating_value_back_into_the_rewards_range(kind):
    """Rewards r = s in [0, 1] at discount 0.9: no value of them leaves [0, 10]. A value whose
    output starts far above that (its last bias lifted, as a run-away bootstrap leaves it: V at
    +500, Q at +50, Q moving at TD3's slower step) is fitted for a few hundred steps: with
    `value_bound` its targets are clipped to the rows' range, so it falls to it (measured: V 6.3,
    Q 11.3); without, each target carries the lift and it stays above (V 88, Q 26)."""
    ends = {}
    for bound in (False, True):
        gen = torch.Generator().manual_seed(0)
        s = torch.rand((2000, 1), generator=gen)
        if kind == "v":
            value = TerminalValue(1, [32, 32], discount=0.9, tau=0.05, generator=gen, bound=bound)
            value.net[-1].bias.data += 50.0  # x scale 10: +500
            value.target.load_state_dict(value.net.state_dict())
            value.fit(s, s[:, 0], s, s.mean(0), s.std(0), torch.optim.Adam(value.net.parameters(), lr=3e-3), 400, 256, gen)
        else:
            value = PolicyValue(1, 1, [32, 32], discount=0.9, tau=0.05, generator=gen, bound=bound)
            value.q[-1].bias.data += 5.0
            value.q_target.load_state_dict(value.q.state_dict())
            a = torch.rand((2000, 1), generator=gen) * 2 - 1
            value.fit(s, a, s[:, 0], s, s.mean(0), s.std(0), value.optimizers(), 600, 256, gen)
        with torch.no_grad():
            ends[bound] = value(s).mean().item()
    assert ends[True] < 13.0 and ends[False] > 20.0, ends


def test_value_heads_agree_on_the_data_and_pessimism_marks_down_where_they_do_not():
    """`value_ensemble` heads, each on its own bootstrap draw against its own target head, learn
    the same discounted sum (10 s) where the data is (s in [0, 1]) and part ways off it (s = 3);
    the planner's score is their mean minus `value_pessimism` x their std, so a state only the
    extrapolation rates high is marked down."""
    gen = torch.Generator().manual_seed(0)
    value = TerminalValue(1, [32, 32], discount=0.9, tau=0.05, generator=gen, heads=5, pessimism=1.0)
    s = torch.rand((2000, 1), generator=gen)
    optimizer = torch.optim.Adam(value.net.parameters(), lr=3e-3)
    metrics = value.fit(s, s[:, 0], s, s.mean(0), s.std(0), optimizer, updates=3000, batch=256, generator=gen)
    probe = torch.tensor([[0.1], [0.5], [0.9], [3.0]])
    with torch.no_grad():
        heads, score = value.each(probe), value(probe)
    np.testing.assert_allclose(heads[:, :3].numpy(), 10 * probe[:3, 0].expand(5, -1).numpy(), atol=0.4)
    spread = heads.std(dim=0)
    assert spread[3] > 10 * spread[:3].max(), spread  # off the data they disagree
    torch.testing.assert_close(score, heads.mean(dim=0) - spread)
    assert 0.0 < metrics["value_head_std"] < 0.3


def test_the_probe_takes_one_head_of_several_as_a_value_of_its_own():
    """`mpc_probe.one_head`: head k alone, its target head with it, scores what head k scored."""
    value = TerminalValue(3, [8, 8], discount=0.9, tau=0.05, generator=torch.Generator().manual_seed(0), heads=4, pessimism=1.0)
    x = torch.randn((7, 3), generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        for head in range(4):
            alone = mpc_probe.one_head(value, head)
            torch.testing.assert_close(alone(x), value.each(x)[head])
            torch.testing.assert_close(alone.each(x, target=True)[0], value.each(x, target=True)[head])


def test_value_heads_need_a_value_and_pessimism_needs_two_heads():
    with pytest.raises(ValueError, match="'value_ensemble' \\(5\\) gives the terminal value heads: it needs 'terminal_value: true'"):
        MPCSpec(value_ensemble=5)
    with pytest.raises(ValueError, match="'value_pessimism' \\(1.0\\) weighs the terminal value's heads: it needs 'terminal_value: true'"):
        MPCSpec(value_pessimism=1.0)
    with pytest.raises(ValueError, match="'value_pessimism' .* needs 'value_ensemble' >= 2"):
        MPCSpec(terminal_value=True, discount=0.99, value_pessimism=1.0)


def test_a_terminal_value_needs_a_discount():
    with pytest.raises(ValueError, match="'terminal_value' needs 'discount' < 1"):
        MPCSpec(terminal_value=True)


@pytest.mark.parametrize("planner", ["cem", "mppi", "random_shooting"])
def test_each_planner_finds_the_best_sequence_of_a_known_return(planner):
    """Return = -sum_t (a_t - target_t)^2 with a different target per env: CEM and MPPI converge
    near it; random shooting beats the average random sequence by far."""
    target = torch.tensor([[[0.5, -0.3]] * 4, [[-0.6, 0.2]] * 4])  # 2 envs, horizon 4, 2-D actions

    def score(candidates: torch.Tensor) -> torch.Tensor:
        return -((candidates - target[:, None]) ** 2).sum(dim=(2, 3))

    spec = MPCSpec(planner=planner, horizon=4, population=300, elites=30, iterations=6)
    result = plan(spec, score, torch.zeros(2, 4, 2), torch.Generator().manual_seed(0))
    error = ((result - target) ** 2).sum(dim=(1, 2))
    if planner == "random_shooting":
        assert (error < 1.6).all(), error  # a uniform sequence is 4.0 and 3.9 off on average
    else:
        assert (error < 0.05).all(), error


TASK = {
    "base": str(ROOT / "tasks/point_mass/semicircle.yaml"),
    "name": "point-reach",
    "goals": {"observable": True, "train": {"count": 20}, "test": {"count": 20}},
    "stages": [{"name": "reach",
                # negative distance: the planner sees the same slope everywhere, also at the goal
                "rewards": [{"term": "tcp_to_goal", "weight": 1.0, "params": {"kernel": "negative"}}],
                "success": {"all": [{"feature": "tcp_to_goal_distance", "below": 0.1}]}}],
}
# a stage before reach that pays for moving away from the goal, never succeeding (a budget promotes it)
AWAY = {"name": "away", "rewards": [{"term": "tcp_to_goal", "weight": -1.0, "params": {"kernel": "negative"}}],
        "success": {"all": [{"feature": "tcp_to_goal_distance", "above": 10.0}]}}
AGENT = {
    "base": str(ROOT / "agents/mpc.yaml"), "name": "mpc-small",
    "mpc": {"hidden_sizes": [64, 64], "steps_per_update": 400, "model_updates": 150, "random_steps": 400},
    "ppo": {"num_envs": 4},
}


def write_task_with_away(folder) -> None:
    """The test task with the `away` stage before reach (after `write`, which writes it without)."""
    (folder / "task.yaml").write_text(yaml.safe_dump({**TASK, "stages": [AWAY, *TASK["stages"]]}))


def write(folder, total_steps: int, mpc: dict | None = None, **curriculum) -> object:
    (folder / "task.yaml").write_text(yaml.safe_dump(TASK))
    (folder / "agent.yaml").write_text(yaml.safe_dump({**AGENT, "mpc": {**AGENT["mpc"], **(mpc or {})}}))
    doc = {"name": "mpc-point", "agent": "agent.yaml", "total_steps": total_steps, "phases": [{"task": "task.yaml"}],
           "evaluation": {"every_steps": 1200, "episodes": 20, "split": "test"}, "checkpoint": {"every_steps": 400}, **curriculum}
    path = folder / "curriculum.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.parametrize("mpc", [{}, {"terminal_value": True, "discount": 0.95},
                                 {"terminal_value": True, "discount": 0.95, "value_policy": True, "prior_trajectories": 3}],
                         ids=["model-only", "terminal-value", "policy-value"])
def test_mpc_learns_to_reach_observed_goals_through_the_curriculum_and_resumes(tmp_path, capsys, mpc):
    """400 random steps, then planning with the model refitted every 400 steps: the held-out goals
    (20, on the semicircle, 1 m away, within 0.1 m) are reached within 2,000 steps, where random
    actions never do. Then `--resume` continues with the model's data (and the terminal value's
    weights), `taskforge eval` plays it, and a curriculum with `init_from` starts from its model
    and data."""
    cur = write(tmp_path, total_steps=1600, mpc=mpc)
    run = train(cur, run_dir=tmp_path / "run", progress=False)
    first = read_jsonl(run / "metrics.jsonl")
    assert first[0]["step"] == 400 and first[0]["buffer_size"] == 400.0
    train(cur, run_dir=run, steps=2400, resume=True, progress=False)
    metrics = read_jsonl(run / "metrics.jsonl")
    assert [m["step"] for m in metrics] == [400, 800, 1200, 1600, 2000, 2400]
    assert metrics[-1]["buffer_size"] == 2400.0  # the data survived the resume
    assert metrics[-1]["model_obs_mse"] < 1e-3
    if mpc:  # the reward is minus the distance, so the value of any behaviour is negative
        assert all(m["value_mean"] < 0 and np.isfinite(m["value_loss"]) for m in metrics)
    out = tmp_path / "eval.json"
    assert main(["eval", str(run), "--episodes", "20", "--out", str(out)]) == 0
    (row,) = json.loads(out.read_text())["rows"]
    # with the value: V has seen 2,400 steps of data here and adds its error to short plans
    # (at the fixed seed 0.75 measured on an AMD EPYC, 0.55 on an Intel Xeon: their matrix
    # kernels round differently, and the run follows); random actions reach none of these goals
    assert row["success_rate"] >= (0.4 if mpc else 0.8), row
    if not mpc:  # `init_from`: a new curriculum starts from this run's model and data
        rarely = {"every_steps": 100_000, "episodes": 20, "split": "test"}  # planning is the cost: evaluate at the start only
        continued = train(write(tmp_path, total_steps=400, init_from="run", evaluation=rarely), run_dir=tmp_path / "continued", progress=False)
        start, first = read_jsonl(continued / "metrics.jsonl")[:2]
        # it plans with the loaded model before any update of its own: the held-out goals are reached
        assert start["step"] == 0 and start["eval_success_rate"] >= 0.8, start
        assert start["stage"] == "reach"  # a curve read per stage keeps this first point
        assert first["step"] == 400 and first["buffer_size"] == 2400.0 + 400.0  # and refits on the source's data too


def test_after_a_promotion_the_reward_learns_from_the_new_stage_alone(tmp_path):
    """A curriculum changes the reward, not the motion. A first stage pays for moving away from
    the goal (promoted by its 1,200-step budget), the next for reaching it: the first stage's rows
    carry the opposite reward on the same states. The agent's reward, predicted on those rows
    after the promotion, is the reach stage's (learnt from every row it is not: it follows the
    rows' own labels), and the planner heads for the goal from those states. The
    stage tags survive a checkpoint, map by name onto another agent (`init_from`), and a
    checkpoint without them loads with every row counted."""
    cur = write(tmp_path, total_steps=2800, promotion={"max_steps": 1200},
                evaluation={"every_steps": 100_000, "episodes": 20, "split": "test"})
    write_task_with_away(tmp_path)
    run = train(cur, run_dir=tmp_path / "run", progress=False)
    metrics = read_jsonl(run / "metrics.jsonl")
    assert metrics[-1]["stage"] == "reach"
    assert metrics[-1]["reward_rows"] < metrics[-1]["buffer_size"]  # the away stage's rows are left out

    agent = load_run(run / "final.pt").agent
    assert agent.stage_names == ["away", "reach"] and agent.stage == 1
    old = agent.buffer.rows_of(0)
    assert len(old) >= 1000
    x, _ = agent.buffer.inputs_and_targets(old)
    members = agent.model.members
    _, predicted = agent.model.mean_prediction(x[None, :, :4].expand(members, -1, -1), x[None, :, 4:].expand(members, -1, -1))
    # recorded: +distance (away's reward); predicted: the reach stage's -distance on the same states
    recorded = agent.buffer.rewards[old]
    # measured: correlation -0.99 and 0.11 off; fitted on every row, +0.41 and 2.2 off
    assert torch.corrcoef(torch.stack([predicted.mean(dim=0), recorded]))[0, 1] < -0.9
    assert (predicted.mean(dim=0) + recorded).abs().mean() < 0.25
    # and the planner heads for the goal from where the away stage went (cosine of the first
    # action with goal - position; measured 0.89, and -0.47 with the reward fitted on every row)
    obs = agent.buffer.obs[old[:: len(old) // 64]].numpy()
    action, _ = agent.act(obs)
    toward = obs[:, 2:] - obs[:, :2]
    assert ((action * toward).sum(axis=1) / np.linalg.norm(action, axis=1) / np.linalg.norm(toward, axis=1)).mean() > 0.6

    state = agent.state_dict()
    other = MPCAgent(agent.spec, agent.observation_space, agent.action_space, seed=0)
    other.add_demonstrations(np.zeros((3, 4), np.float32), np.zeros((3, 2), np.float32), np.zeros(3, np.float32), np.arange(3) == 0, "reach")
    other.load_weights(state)  # its names: reach first, then away
    assert other.stage_names == ["reach", "away"] and len(other.buffer.rows_of(1)) == len(old)
    for key in ("stage_names", "stage"):
        del state[key]
    del state["buffer"]["stages"]
    other.load_state_dict(state)  # a checkpoint from before the tags
    assert other.stage is None and len(other.buffer.rows_of(None)) == len(other.buffer.rows_of(0)) == agent.buffer.size


def _point_mass_walks(episodes: int = 40, length: int = 50) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Random walks of a point mass, each with a random goal: observations (position, goal), actions,
    the distance to the goal at each step, and the episode starts."""
    rng = np.random.default_rng(0)
    goal = rng.uniform(-1, 1, (episodes, 1, 2))
    steps = rng.uniform(-1, 1, (episodes, length, 2))
    position = np.clip(rng.uniform(-1, 1, (episodes, 1, 2)) + 0.05 * np.cumsum(steps, axis=1), -1.5, 1.5)
    obs = np.concatenate([position, np.broadcast_to(goal, position.shape)], axis=2).reshape(-1, 4).astype(np.float32)
    distance = np.linalg.norm(obs[:, :2] - obs[:, 2:], axis=1).astype(np.float32)
    return obs, steps.reshape(-1, 2).astype(np.float32), distance, np.arange(len(obs)) % length == 0


def _value_agent(**mpc) -> MPCAgent:
    """A point-mass MPC agent with a small terminal value (`mpc` overrides)."""
    spec = AgentSpec.model_validate({"name": "v", "algo": "mpc", "mpc": {
        "ensemble_size": 2, "hidden_sizes": [32, 32], "particles": 2, "discount": 0.9, "terminal_value": True,
        "model_updates": 400, "value_tau": 0.05} | mpc})
    return MPCAgent(spec, Box(-np.inf, np.inf, (4,), np.float32), Box(-1.0, 1.0, (2,), np.float32), seed=0)


def _ranks_by_closeness(agent: MPCAgent, obs: np.ndarray, distance: np.ndarray) -> float:
    """The correlation of the agent's V with minus the distance to the goal on `obs`."""
    with torch.no_grad():
        value = agent.value(torch.as_tensor(obs))
    return torch.corrcoef(torch.stack([value, -torch.as_tensor(distance)]))[0, 1].item()


def test_the_terminal_value_learns_from_the_stage_being_trained_alone():
    """The value, like the reward, fits the stage being trained's rows. The same random walks of
    a point mass are in the buffer twice: as the reach stage's episodes (reward: minus the
    distance to the goal) and as an earlier stage's that paid for the distance itself. Trained
    on reach, the value ranks those states as reach does, by closeness to the goal; fitted on
    every row, the two rewards cancel on the same states and it ranks them by nothing."""
    obs, actions, distance, starts = _point_mass_walks()
    agent = _value_agent()
    agent.add_demonstrations(obs, actions, -distance, starts, "reach")  # the stage trained
    agent.add_demonstrations(obs, actions, distance, starts, "away")
    metrics = agent.update()
    assert metrics["reward_rows"] == metrics["buffer_size"] / 2
    # measured: correlation with -distance 0.99; with the value fitted on every row, 0.30
    assert _ranks_by_closeness(agent, obs, distance) > 0.8


def test_value_updates_sets_the_values_steps_apart_from_the_models():
    """`value_updates`: the value takes its own number of steps per fit (TD-MPC2's one per env
    step), the model keeps `model_updates`; with too few the value has not learnt to rank the
    states by closeness yet, with the value's own count it has."""
    obs, actions, distance, starts = _point_mass_walks()
    few, many = _value_agent(model_updates=20), _value_agent(model_updates=20, value_updates=400)
    for agent in (few, many):
        agent.add_demonstrations(obs, actions, -distance, starts, "reach")
        agent.update()
    steps = [next(iter(a.value_optimizer.state.values()))["step"].item() for a in (few, many)]
    assert steps == [20, 400]
    assert next(iter(many.optimizer.state.values()))["step"].item() == 20  # the model's own
    assert _ranks_by_closeness(many, obs, distance) > 0.8 > _ranks_by_closeness(few, obs, distance)
    with pytest.raises(ValueError, match="'value_updates' .* fits the terminal value"):
        MPCSpec(value_updates=5)


def test_value_relabel_fits_the_earlier_stages_rows_with_the_reward_networks_reward_for_this_one():
    """`value_relabel`: the value also fits the earlier stage's rows, their reward the model's
    reward network's for the stage being trained, not the reward they were stored with. The same
    random walks are in the buffer as reach's (minus the distance) and as an earlier stage's (plus
    the distance): relabelled, those rows say what reach's do and the value still ranks states by
    closeness (fitted on every row as stored, the two rewards cancel: 0.30, the test above); the
    stage's own rows keep their stored reward bit for bit."""
    obs, actions, distance, starts = _point_mass_walks()
    agent = _value_agent(value_relabel=True)
    agent.add_demonstrations(obs, actions, -distance, starts, "reach")  # the stage trained
    agent.add_demonstrations(obs, actions, distance, starts, "away")
    metrics = agent.update()
    assert metrics["value_relabelled_rows"] == metrics["buffer_size"] - metrics["reward_rows"] == metrics["reward_rows"]
    assert _ranks_by_closeness(agent, obs, distance) > 0.8
    inputs, targets = agent.buffer.inputs_and_targets()
    rows = agent.buffer.rows_of(agent.stage)
    relabelled = agent._stage_rewards(inputs, targets[:, -1], rows)
    assert torch.equal(relabelled[rows], targets[rows, -1])
    away = agent.buffer.rows_of(agent._tag("away"))
    assert torch.corrcoef(torch.stack([relabelled[away], -targets[away, -1]]))[0, 1] > 0.9  # reach's reward there
    single = _value_agent(value_relabel=True)  # one stage: nothing to relabel
    single.add_demonstrations(obs, actions, -distance, starts, "reach")
    assert "value_relabelled_rows" not in single.update()
    with pytest.raises(ValueError, match="'value_relabel' \\(True\\) widens the terminal value's rows"):
        MPCSpec(value_relabel=True)


def test_a_fresh_refit_of_the_value_forgets_what_it_learnt_before(tmp_path):
    """`value_refit_every`: a V that learnt the opposite of the reward (the primacy bias in its
    sharpest form: it paid for the distance, the stage pays for closeness) is not undone by the
    online fit's few steps; a fresh refit is, at the first fit and at each multiple of the period,
    not between them. The count of refits survives a checkpoint."""
    obs, actions, distance, starts = _point_mass_walks()

    def misled(agent: MPCAgent) -> MPCAgent:  # V fitted to the opposite reward, on the same states
        x = torch.as_tensor(obs)
        agent.value.fit(x, torch.as_tensor(distance), x, x.mean(0), x.std(0), agent.value_optimizer, 1500, 256, agent.generator)
        assert _ranks_by_closeness(agent, obs, distance) < -0.5
        return agent

    # measured: misled -1.00; after 30 online steps still -1.00; after each fresh refit +0.99
    online = misled(_value_agent(model_updates=30))
    online.add_demonstrations(obs, actions, -distance, starts, "reach")
    assert "value_refit" not in online.update()
    assert _ranks_by_closeness(online, obs, distance) < 0.5  # 30 online steps leave it misled

    refits = _value_agent(model_updates=30, value_refit_every=1000, value_refit_updates=1500)
    refits.add_demonstrations(obs, actions, -distance, starts, "reach")
    assert refits.update()["value_refit"] == 1.0  # the first fit: a fresh V on the whole buffer
    assert _ranks_by_closeness(refits, obs, distance) > 0.8
    misled(refits).global_step = 999
    assert "value_refit" not in refits.update()  # between refits the online fit goes on from it
    assert _ranks_by_closeness(refits, obs, distance) < 0.5
    torch.save(refits.state_dict(), tmp_path / "agent.pt")
    resumed = _value_agent(model_updates=30, value_refit_every=1000, value_refit_updates=1500)
    resumed.load_state_dict(torch.load(tmp_path / "agent.pt", weights_only=True))
    resumed.global_step = 1000  # a multiple of the period passed: refitted afresh
    assert resumed.update()["value_refit"] == 1.0
    assert _ranks_by_closeness(resumed, obs, distance) > 0.8
    assert "value_refit" not in resumed.update()


def test_an_agent_with_value_heads_ranks_states_and_resumes_them_only_into_as_many_heads(tmp_path):
    """Through the agent: `value_ensemble` heads, trained on the stage's rows, rank the reach
    walks' states by closeness to the goal as one V does; a checkpoint restores them, and starting
    an agent with another number of heads from it (`init_from`) is refused, not reshaped."""
    obs, actions, distance, starts = _point_mass_walks()
    agent = _value_agent(value_ensemble=3, value_pessimism=1.0)
    agent.add_demonstrations(obs, actions, -distance, starts, "reach")
    metrics = agent.update()
    assert metrics["value_head_std"] > 0.0
    assert _ranks_by_closeness(agent, obs, distance) > 0.8
    torch.save(agent.state_dict(), tmp_path / "agent.pt")
    resumed = _value_agent(value_ensemble=3, value_pessimism=1.0)
    resumed.load_state_dict(torch.load(tmp_path / "agent.pt", weights_only=True))
    x = torch.as_tensor(obs[:100])
    with torch.no_grad():
        torch.testing.assert_close(resumed.value(x), agent.value(x))
    with pytest.raises(WeightsMismatch, match="terminal value 'net.0.weight' has shape"):  # `init_from`
        _value_agent().load_weights(torch.load(tmp_path / "agent.pt", weights_only=True))


def test_the_policy_value_ranks_states_proposes_its_policys_rollouts_and_resumes(tmp_path):
    """`value_policy` through the agent: Q(s, pi(s)) fitted on the reach walks' rows ranks their
    states by closeness to the goal as V does; with `prior_trajectories` its policy is the one
    that proposes, and stays so across a fresh refit; a checkpoint restores Q, pi and both
    optimizers (the policy saved once, with the value)."""
    obs, actions, distance, starts = _point_mass_walks()
    agent = _value_agent(value_policy=True, prior_trajectories=3, value_refit_every=1000, value_refit_updates=600)
    assert agent.prior is agent.value.policy
    toward = np.clip(obs[:, 2:] - obs[:, :2], -1.0, 1.0)  # a warm start's demos are cloned into that policy
    assert agent.fit_prior(obs, toward, epochs=30, batch_size=256, learning_rate=1e-3)["prior_bc_mse"] < 0.05
    assert np.abs(agent.prior_act(obs[:200]) - toward[:200]).mean() < 0.2
    agent.add_demonstrations(obs, actions, -distance, starts, "reach")
    metrics = agent.update()
    assert metrics["value_refit"] == 1.0 and agent.prior is agent.value.policy  # the refit's new policy proposes
    assert _ranks_by_closeness(agent, obs, distance) > 0.8
    first, _ = agent.act(obs[:5])
    assert first.shape == (5, 2) and np.all(np.abs(first) <= 1.0)
    state = agent.state_dict()
    assert "prior" not in state and {"value", "policy_optimizer"} <= set(state)
    torch.save(state, tmp_path / "agent.pt")
    resumed = _value_agent(value_policy=True, prior_trajectories=3, value_refit_every=1000, value_refit_updates=600)
    resumed.load_state_dict(torch.load(tmp_path / "agent.pt", weights_only=True))
    x = torch.as_tensor(obs[:100])
    with torch.no_grad():
        torch.testing.assert_close(resumed.value(x), agent.value(x))
        torch.testing.assert_close(resumed.prior(x), agent.prior(x))
    assert resumed.policy_optimizer.state_dict()["state"].keys() == agent.policy_optimizer.state_dict()["state"].keys()
    with pytest.raises(WeightsMismatch):  # `init_from` a run whose terminal value is V
        _value_agent().load_weights(torch.load(tmp_path / "agent.pt", weights_only=True))


def test_value_start_keeps_the_value_and_its_policy_out_of_the_plans_until_its_first_fit(tmp_path):
    """`value_start`: before that many env steps the value is not fitted (its weights stay as
    drawn) and its pi proposes nothing (a search that would start from pi's rollout starts from
    the previous plan); at the first update past it the value has its fresh first fit, ranks
    states as the reward does, proposes, and a checkpoint remembers that it has started."""
    obs, actions, distance, starts = _point_mass_walks()
    settings = {"value_policy": True, "prior_trajectories": 2, "value_start": 2000, "value_refit_every": 100_000_000,
                "value_refit_updates": 600, "momentum": 0.99, "iterations": 1, "population": 4, "elites": 2}
    agent = _value_agent(**settings)
    agent.add_demonstrations(obs, actions, -distance, starts, "reach")
    drawn = copy.deepcopy(agent.value.state_dict())
    metrics = agent.update()
    assert "value_loss" not in metrics and not agent.value_started
    assert all(torch.equal(drawn[k], v) for k, v in agent.value.state_dict().items())
    previous = torch.full((4, agent.mpc.horizon, 2), 0.7)
    first, _ = agent.act(obs[:4], previous)
    np.testing.assert_allclose(first, np.full((4, 2), 0.7, np.float32), atol=0.05)  # the previous plan, not pi's
    agent.global_step = 2000
    metrics = agent.update()
    assert metrics["value_refit"] == 1.0 and agent.value_started
    assert _ranks_by_closeness(agent, obs, distance) > 0.8
    first, _ = agent.act(obs[:4], previous)
    np.testing.assert_allclose(first, agent.prior_act(obs[:4]), atol=0.05)  # now from pi's own rollout
    resumed = _value_agent(**settings)
    resumed.load_state_dict(agent.state_dict())
    assert resumed.value_started
    with pytest.raises(ValueError, match="'value_start' \\(2000\\) delays the terminal value"):
        MPCSpec(value_start=2000)


@pytest.mark.parametrize("from_prior", [True, False])
def test_the_search_starts_from_the_prior_or_from_the_previous_plan(from_prior):
    """`search_from_prior`: with a CEM that barely moves its mean (momentum 0.99), the plan's
    first action is where the search started: the proposing policy's own action, or the
    previous plan carried in the state (TD-MPC's warm start; the proposals only join)."""
    obs, _, _, _ = _point_mass_walks(episodes=1, length=4)
    agent = _value_agent(value_policy=True, prior_trajectories=2, search_from_prior=from_prior, momentum=0.99,
                         iterations=1, population=4, elites=2)
    previous = torch.full((4, agent.mpc.horizon, 2), 0.7)
    first, _ = agent.act(obs, previous)
    expected = agent.prior_act(obs) if from_prior else np.full((4, 2), 0.7, np.float32)
    np.testing.assert_allclose(first, expected, atol=0.05)


def test_the_policy_value_is_a_kind_of_terminal_value_with_one_head(tmp_path, capsys):
    """Its policy proposes without demos: `validate` accepts `prior_trajectories` with no warm
    start there, and still refuses it without `value_policy` (test above)."""
    learnt = {"terminal_value": True, "discount": 0.95, "value_policy": True, "prior_trajectories": 3}
    assert main(["validate", str(write(tmp_path, total_steps=400, mpc=learnt))]) == 0, capsys.readouterr().err
    with pytest.raises(ValueError, match="'value_policy' \\(True\\) is the terminal value's kind"):
        MPCSpec(value_policy=True)
    with pytest.raises(ValueError, match="'value_policy' has one Q of one policy"):
        MPCSpec(value_policy=True, terminal_value=True, discount=0.9, value_ensemble=3)


def test_a_value_refit_needs_a_value():
    with pytest.raises(ValueError, match="'value_refit_every' .* needs 'terminal_value: true'"):
        MPCSpec(value_refit_every=1000)
    with pytest.raises(ValueError, match="'value_bound' \\(True\\) clips the terminal value's targets"):
        MPCSpec(value_bound=True)


def test_a_checkpoint_saves_each_observation_once_and_restores_the_buffer_bit_for_bit(tmp_path):
    """The point-mass task's real collections (4 envs, 20-step episodes, a buffer of 1,000 rows
    overwritten past its capacity): every `next_obs` but those an episode ended on (and the 4
    newest, whose landing is no row yet) repeats a row's `obs`, so the checkpoint saves it as a
    link. Loaded, every row is restored exactly, and a checkpoint from before the links (every
    `next_obs` saved) loads the same."""
    write(tmp_path, total_steps=1400, mpc={"random_steps": 1400, "steps_per_update": 1400, "buffer_size": 1000})
    spec, task = load_agent_spec(tmp_path / "agent.yaml"), load_task(tmp_path / "task.yaml")
    envs = make_vector_env([lambda: TaskEnv(task, tmp_path / "task.yaml") for _ in range(4)], spec.runtime)
    agent = MPCAgent(spec, envs.single_observation_space, envs.single_action_space, seed=0)
    agent.collect(envs)
    envs.close()
    buffer = agent.buffer
    assert buffer.size == 1000 and buffer.cursor == 400  # the ring wrapped
    torch.save(buffer.state_dict(), tmp_path / "buffer.pt")
    saved = torch.load(tmp_path / "buffer.pt", weights_only=True)
    # ~1 row in 20 ended an episode: only those (and the newest 4) are saved whole
    assert 40 <= len(saved["next_obs"]) < 0.1 * buffer.size
    linked = saved["landed_at"] >= 0
    assert torch.equal(buffer.next_obs[:1000][linked], buffer.obs[saved["landed_at"][linked].long()])

    old_style = {**saved, "next_obs": buffer.next_obs[:1000].clone()}
    del old_style["landed_at"]
    for state in (saved, old_style):
        restored = TransitionBuffer(1000, buffer.obs.shape[1], buffer.actions.shape[1])
        restored.load_state_dict(state)
        for field in ("obs", "actions", "rewards", "next_obs", "stages"):
            assert torch.equal(getattr(restored, field), getattr(buffer, field)), field
        assert (restored.size, restored.cursor) == (buffer.size, buffer.cursor)


def test_the_random_first_trial_lasts_random_steps_across_fits_and_not_after_demos(tmp_path):
    """`random_steps` 200 with a fit every 100: both first collections are random (the planner is
    never asked), the third plans every step; an agent whose data was given (demos) plans at once."""
    write(tmp_path, total_steps=300, mpc={"random_steps": 200, "steps_per_update": 100})
    spec, task = load_agent_spec(tmp_path / "agent.yaml"), load_task(tmp_path / "task.yaml")
    envs = make_vector_env([lambda: TaskEnv(task, tmp_path / "task.yaml") for _ in range(4)], spec.runtime)
    agent = MPCAgent(spec, envs.single_observation_space, envs.single_action_space, seed=0)
    planned = []
    plan_once = agent.act
    agent.act = lambda *args, **kw: planned.append(1) or plan_once(*args, **kw)  # counts the planner's calls
    for collection in range(3):
        agent.collect(envs)
        assert len(planned) == (25 if collection == 2 else 0), collection  # 100 steps / 4 envs
        agent.update()
    given = MPCAgent(spec, envs.single_observation_space, envs.single_action_space, seed=0)
    data = agent.buffer.state_dict()  # as if they were a demo episode of 200 steps
    given.add_demonstrations(data["obs"][:200].numpy(), data["actions"][:200].numpy(), data["rewards"][:200].numpy(),
                             np.arange(200) == 0, "reach")
    given.update()
    given.act = lambda *args, **kw: planned.append(1) or MPCAgent.act(given, *args, **kw)
    given.collect(envs)
    assert len(planned) == 25 + 25
    envs.close()


def test_mpc_agent_files_are_checked_like_any_other(tmp_path, capsys):
    bad = {"name": "x", "algo": "mpc", "mpc": {"particles": 7, "ensemble_size": 5}}
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(bad))
    assert main(["validate", str(tmp_path / "agent.yaml")]) == 2
    assert "multiple of 'ensemble_size'" in capsys.readouterr().err
    with pytest.raises(ValueError, match="needs algo: mpc"):
        AgentSpec.model_validate({"name": "x", "mpc": {}})


CUDA = torch.cuda.is_available()


@pytest.mark.skipif(CUDA, reason="the message of a machine without CUDA")
def test_a_missing_gpu_is_a_one_line_error_and_a_gpu_trained_run_evaluates_on_the_cpu(tmp_path, capsys):
    """`mpc.device: cuda` where torch finds none stops `train` with one line naming the agent file
    and the field; a run whose stored config says cuda still loads and evaluates on the CPU."""
    cur = write(tmp_path, total_steps=400, mpc={"device": "cuda"})
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "gpu")]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    assert "agent.yaml" in line and "mpc.device" in line and "'cuda'" in line and "set it to cpu" in line
    rarely = {"every_steps": 100_000, "episodes": 2, "split": "test"}
    run = train(write(tmp_path, total_steps=400, evaluation=rarely), run_dir=tmp_path / "cpu", progress=False)
    path = run / "final.pt"
    state = torch.load(path, map_location="cpu", weights_only=True)
    state["config"]["agent"]["mpc"]["device"] = "cuda"  # as if it had been trained on a GPU
    torch.save(state, path)
    loaded = load_run(run)
    assert loaded.agent.device.type == "cpu"
    assert main(["eval", str(run), "--episodes", "2", "--out", str(tmp_path / "eval.json")]) == 0


@pytest.mark.skipif(not CUDA, reason="needs a CUDA device (run on a GPU machine)")
def test_on_a_gpu_the_agent_starts_from_the_cpu_weights_and_learns_to_reach(tmp_path):
    """The same seed gives the same initial model on either device (it is built on the CPU),
    and on the GPU the agent trains and reaches held-out goals as on the CPU. Measured on an H200
    (2,400 steps, seeds 0-3, no resume): GPU 0.50 / 0.60 / 1.00 / 0.65, CPU 0.45 / 0.55 / 1.00 /
    0.65; random actions reach none (the draws differ by device, so the runs do too)."""
    cur = write(tmp_path, total_steps=2400, mpc={"device": "cuda"})
    spec = load_agent_spec(tmp_path / "agent.yaml")
    space, actions = Box(-np.inf, np.inf, (4,), np.float32), Box(-1.0, 1.0, (2,), np.float32)
    weights = [MPCAgent(spec.with_planning(device=d), space, actions, seed=3).model.state_dict() for d in ("cpu", "cuda")]
    for name, tensor in weights[0].items():
        torch.testing.assert_close(weights[1][name].cpu(), tensor)
    run = train(cur, run_dir=tmp_path / "run", progress=False)
    out = tmp_path / "eval.json"
    assert main(["eval", str(run), "--episodes", "20", "--out", str(out)]) == 0
    (row,) = json.loads(out.read_text())["rows"]
    assert row["success_rate"] >= 0.4, row


class StraightToGoal:
    """A scripted point-mass expert (the point mass has none of its own): full speed at the goal."""

    name = "straight"

    def reset(self, env) -> None:
        pass

    def __call__(self, env) -> np.ndarray:
        features = env.backend.features()
        step = (features["goal_pos"] - features["tcp_pos"])[:2] / 0.1
        return np.clip(step, -1.0, 1.0).astype(np.float32)


def test_mpc_warm_start_seeds_the_models_data_and_refuses_dagger(tmp_path, capsys):
    cur = write(tmp_path, total_steps=800, warm_start={"demos": "demos.npz", "dagger": {"rounds": 1}})
    task = load_task(tmp_path / "task.yaml")
    demos = record(TaskEnv(task, tmp_path / "task.yaml", stage="reach"), StraightToGoal(), episodes=4, keep_failed=True)
    save(demos, tmp_path / "demos.npz")
    assert main(["validate", str(cur)]) == 2
    assert "warm_start.dagger.rounds" in capsys.readouterr().err
    cur = write(tmp_path, total_steps=800, warm_start={"demos": "demos.npz"})
    run = train(cur, run_dir=tmp_path / "warm", progress=False)
    metrics = read_jsonl(run / "metrics.jsonl")
    # every demo step with a successor in its episode is a transition; the expert's steps count
    assert metrics[0]["demo_transitions"] == demos.num_steps - demos.num_episodes
    assert metrics[0]["step"] == metrics[0]["expert_steps"] == demos.num_steps
    # the evaluation right after the warm start names its stage: benchmarks/model_based.py reads
    # each run's curve on its stage, and the curve starts where the demos left it
    assert "eval_success_rate" in metrics[0] and metrics[0]["stage"] == "reach"
    assert model_based.curve(metrics, "reach")[0] == (demos.num_steps, metrics[0]["eval_success_rate"])
    # the model was fitted on them before the first plan: no random phase, the buffer starts there
    assert metrics[1]["buffer_size"] == demos.num_steps - demos.num_episodes + 400


def test_an_mpc_warm_start_over_phases_that_end_in_different_stages_must_name_one(tmp_path, capsys):
    """The demos' rewards train one stage's reward, so `phase: all` over phases whose last stages
    differ is refused before anything runs, naming the stages; naming one is accepted."""
    phases = [{"task": "task.yaml", "stages": ["away"]}, {"task": "task.yaml", "stages": ["reach"]}]
    cur = write(tmp_path, total_steps=800, phases=phases, warm_start={"generate_episodes": 2, "phase": "all"})
    write_task_with_away(tmp_path)
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "warm_start.stage" in err and "(away, reach)" in err, err
    assert not (tmp_path / "run").exists()
    cur.write_text(cur.read_text().replace("phase: all", "phase: all\n  stage: reach"))
    assert main(["validate", str(cur)]) == 0


def test_an_mpc_warm_start_from_a_demos_file_recorded_over_several_stages_is_refused(tmp_path, capsys):
    """A demos file can hold several stages (recorded with `phase: all`), which `validate` cannot
    see: `train` refuses it in one line at `warm_start.stage`, naming them, and leaves the file be."""
    cur = write(tmp_path, total_steps=800, warm_start={"demos": "demos.npz"})
    write_task_with_away(tmp_path)
    task = load_task(tmp_path / "task.yaml")
    parts = [record(TaskEnv(task, tmp_path / "task.yaml", stage=stage), StraightToGoal(), episodes=1, keep_failed=True)
             for stage in ("away", "reach")]
    saved = save(concatenate(parts), tmp_path / "demos.npz").read_bytes()
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "warm_start.stage" in err and "(away, reach)" in err, err
    assert (tmp_path / "demos.npz").read_bytes() == saved


def test_validate_describes_the_mpc_warm_start_as_the_models_data(capsys, monkeypatch):
    """`taskforge validate` on an MPC curriculum with demos says what they do there (seed the
    model's data), not the PPO warm start's cloning, DAgger and BC term, which MPC does not run."""
    monkeypatch.chdir(ROOT)
    assert main(["validate", "benchmarks/configs/mpc_pick_place_demos.yaml"]) == 0
    [line] = [x for x in capsys.readouterr().out.splitlines() if "warm start from" in x]
    assert "seed the dynamics model's data" in line and "BC" not in line


@pytest.mark.parametrize(("config", "starts_from_prior"), [
    ("benchmarks/configs/mpc_pick_place_demos_prior.yaml", True),  # agents/mpc_demos.yaml: search_from_prior
    ("benchmarks/configs/mpc_push_policy_value_long_demos.yaml", False),  # the value's pi only proposes
])
def test_validate_says_whether_the_search_starts_from_the_proposing_policy(capsys, monkeypatch, config, starts_from_prior):
    """The warm start's summary line says the search starts from the cloned policy only where the
    preset's `search_from_prior` makes it so: a preset that only adds the policy's rollouts to the
    candidates (TD-MPC's arrangement) must not read as LOOP's trust region."""
    monkeypatch.chdir(ROOT)
    assert main(["validate", config]) == 0
    [line] = [x for x in capsys.readouterr().out.splitlines() if "warm start from" in x]
    assert "proposes" in line and ("the search starts from it" in line) == starts_from_prior, line



def test_a_proposal_the_model_scores_best_becomes_the_plan():
    """Whatever the search draws, a proposal with the best return is kept: random shooting's
    argmax returns it, and CEM whose elites are its two copies (no momentum) moves its mean onto it."""
    target = torch.tensor([[[0.9, -0.9]] * 4, [[-0.8, 0.7]] * 4])  # 2 envs, horizon 4

    def score(candidates: torch.Tensor) -> torch.Tensor:
        return -((candidates - target[:, None]) ** 2).sum(dim=(2, 3))

    proposals = torch.stack([torch.zeros(2, 4, 2), target, target], dim=1)  # a poor proposal, the best twice
    for planner in ("random_shooting", "cem"):
        spec = MPCSpec(planner=planner, horizon=4, population=3, elites=2, iterations=1, momentum=0.0)
        result = plan(spec, score, torch.zeros(2, 4, 2), torch.Generator().manual_seed(0), proposals)
        assert torch.allclose(result, target), (planner, result)


def test_the_demos_policy_proposes_plans_from_the_first_step_and_survives_a_resume(tmp_path, capsys, monkeypatch):
    """A search too weak to find the goals alone (random shooting, 2 uniform sequences) reaches
    them right after the warm start when a policy cloned from 4 scripted episodes proposes plans;
    without the prior the same search does not. The prior is in the checkpoint, and needs demos;
    the probe benchmark tells the prior's share from the search's."""
    weak = {"planner": "random_shooting", "population": 2, "elites": 1}
    write(tmp_path, total_steps=400, mpc={**weak, "prior_trajectories": 3})
    assert main(["validate", str(tmp_path / "curriculum.yaml")]) == 2
    assert "mpc.prior_trajectories" in capsys.readouterr().err
    task = load_task(tmp_path / "task.yaml")
    demos = record(TaskEnv(task, tmp_path / "task.yaml", stage="reach"), StraightToGoal(), episodes=4, keep_failed=True)
    save(demos, tmp_path / "demos.npz")
    rarely = {"every_steps": 100_000, "episodes": 20, "split": "test"}  # evaluate after the warm start only
    demos_warm_start = {"demos": "demos.npz", "bc_epochs": 1000}  # 80 steps of demos: 1,000 Adam steps
    after = {}
    for prior in (0, 3):  # the prior's files last: its run resumes from them
        cur = write(tmp_path, total_steps=demos.num_steps + 400, mpc={**weak, "prior_trajectories": prior},
                    warm_start=demos_warm_start, evaluation=rarely)
        run = train(cur, run_dir=tmp_path / f"prior{prior}", progress=False)
        first = read_jsonl(run / "metrics.jsonl")[0]
        after[prior] = first["eval_success_rate"]
        if prior:
            assert first["demo_prior_bc_mse"] < 0.01, first  # the expert's straight line is cloned
    assert after[3] >= 0.6 and after[0] <= 0.2, after  # measured 0.75 and 0.00 (4 demo goals of 20 held out)
    state = torch.load(tmp_path / "prior3/checkpoint.pt", weights_only=True)["agent"]
    assert "prior" in state
    with pytest.raises(ValueError, match="no prior"):
        load_run(tmp_path / "prior0/checkpoint.pt").agent.prior_act(demos.observations[:1])
    train(cur, run_dir=tmp_path / "prior3", steps=demos.num_steps + 800, resume=True, progress=False)
    assert read_jsonl(tmp_path / "prior3/metrics.jsonl")[-1]["step"] == demos.num_steps + 800
    # benchmarks/mpc_prior_probe.py on this run: the cloned expert alone reaches the goals, the weak
    # search without it does not; it records the rows, seed and file name it was asked for
    monkeypatch.setattr(benchmarks.common, "RESULTS", tmp_path / "results")
    monkeypatch.setattr("sys.argv", ["mpc_prior_probe.py", str(tmp_path / "prior3/checkpoint.pt"), "--trials", "8",
                                     "--seed", "7", "--players", "prior", "unguided", "--out", "probe"])
    mpc_prior_probe.main()
    result = json.loads((tmp_path / "results/probe.json").read_text())
    rows = result["rows"]
    assert result["seed"] == 7 and result["trials"] == 8 and len(rows) == 2, result  # no guided rows asked for
    assert rows["prior alone"]["success"] >= 0.5, rows  # measured 0.75 (6 of 8)
    assert rows["planner without the prior (init_std 0.5)"]["success"] <= 0.25, rows  # measured 0.00
    for row in rows.values():  # 8 trials on 8 distinct goals of 20: a miss is a missed goal
        assert len(row["missed_goals"]) == round(8 * (1 - row["success"])) and set(row["missed_goals"]) <= set(range(8))


def demos_run(folder, task: str, stage: str, episodes: int, planned_steps: int, **mpc) -> tuple[object, int]:
    """A small MPC run warm-started from `episodes` scripted episodes of `stage`, then
    `planned_steps` of its own (`mpc`: changes to its `mpc:` block): its final checkpoint and how
    many of its transitions the demos hold (each episode's last observation starts no transition)."""
    demos = generate(ROOT / task, stage=stage, episodes=episodes, seed=3)
    save(demos, folder / "demos.npz")
    agent = {**AGENT, "mpc": {**AGENT["mpc"], "hidden_sizes": [32, 32], "model_updates": 20, **mpc}}
    (folder / "agent.yaml").write_text(yaml.safe_dump(agent))
    doc = {"name": f"{stage}-probe", "agent": "agent.yaml", "total_steps": demos.num_steps + planned_steps,
           "phases": [{"task": str(ROOT / task), "stages": [stage]}], "warm_start": {"demos": "demos.npz"},
           "evaluation": {"every_steps": 100_000, "episodes": 1, "split": "test"}, "checkpoint": {"every_steps": 100_000}}
    (folder / "curriculum.yaml").write_text(yaml.safe_dump(doc))
    run = train(folder / "curriculum.yaml", run_dir=folder / "run", progress=False)
    return run / "final.pt", demos.num_steps - demos.num_episodes


def probe_windows(tmp_path, monkeypatch, checkpoint, window: int) -> dict:
    """benchmarks/mpc_data_probe.py's result for one checkpoint (its step rows under "windows",
    its episode rows under "episodes"), read back from its results file."""
    monkeypatch.setattr(benchmarks.common, "RESULTS", tmp_path / "results")
    monkeypatch.setattr("sys.argv", ["mpc_data_probe.py", str(checkpoint), "--window", str(window), "--out", "probe"])
    mpc_data_probe.main()
    (result,) = json.loads((tmp_path / "results/probe.json").read_text())["runs"].values()
    return result


def test_the_data_probe_counts_the_demos_pushes_toward_the_goal_and_reads_the_buffer_oldest_first(tmp_path, monkeypatch):
    """benchmarks/mpc_data_probe.py on a real push run warm-started from Meta-World's scripted
    pushes: the demos (the buffer's first rows) move the puck toward the goal in most of the steps
    that move it, with the hand at the puck, and never lift it; the untrained planner's steps
    after them do neither; a task without `goal - object` features is a one-line error. A full
    buffer is read from the row its cursor overwrites next."""
    ring = TransitionBuffer(capacity=3, obs_size=1, action_size=1)
    ring.add(*(np.arange(5.0)[:, None],) * 2, np.zeros(5), np.arange(5.0)[:, None], np.arange(5))
    assert ring.obs[ring.oldest_first(), 0].tolist() == [2.0, 3.0, 4.0]
    assert ring.stages[ring.oldest_first()].tolist() == [2, 3, 4]  # each row keeps its own stage

    (tmp_path / "push").mkdir()
    checkpoint, transitions = demos_run(tmp_path / "push", "tasks/metaworld/push.yaml", "push", episodes=2, planned_steps=400)
    expert, planned = probe_windows(tmp_path, monkeypatch, checkpoint, transitions)["windows"]
    assert (expert["from"], expert["to"], planned["to"]) == (0, transitions, transitions + 400), (expert, planned)
    assert expert["toward_goal"] >= 20 and expert["toward_goal"] >= 0.6 * expert["moved"], expert
    assert planned["toward_goal"] <= 0.25 * expert["toward_goal"], planned  # measured: 55 of 58 moves, then 0 of 1
    assert expert["at_object"] >= 0.5 * transitions and planned["at_object"] <= 0.25 * expert["at_object"], (expert, planned)  # 537 of 598, then 0
    assert expert["rose"] <= 2, expert  # a pushed puck slides on the table

    point = write(tmp_path, total_steps=400)  # the point-mass task: no object, no `goal - object`
    train(point, run_dir=tmp_path / "point", progress=False)
    monkeypatch.setattr("sys.argv", ["mpc_data_probe.py", str(tmp_path / "point/final.pt")])
    with pytest.raises(SystemExit, match="observation.relative_positions: true"):
        mpc_data_probe.main()


def test_the_push_probe_scores_meta_worlds_scripted_pushes_with_the_runs_own_model(tmp_path, monkeypatch):
    """benchmarks/mpc_push_probe.py on a real push run warm-started from scripted pushes: it
    compares the model on exactly the scripted steps that moved the puck (counted here from the
    simulator, independently), finds hand-at-puck states before a goalward push and has the run's
    scorer pick one of three sequences at each; a task without `goal - object`, or a folder with no
    run, is a one-line error."""
    (tmp_path / "push").mkdir()
    checkpoint, _ = demos_run(tmp_path / "push", "tasks/metaworld/push.yaml", "push", episodes=2, planned_steps=400)
    monkeypatch.setattr(benchmarks.common, "RESULTS", tmp_path / "results")
    monkeypatch.setattr("sys.argv", ["mpc_push_probe.py", str(checkpoint), "--episodes", "1", "--repeats", "1", "--out", "push"])
    mpc_push_probe.main()
    (result,) = json.loads((tmp_path / "results/push.json").read_text())["runs"]

    (episode,) = mpc_push_probe.scripted_episodes(str(ROOT / "tasks/metaworld/push.yaml"), "push", 1)
    moved = int((np.linalg.norm(episode.next_obs[:, 4:7] - episode.obs[:, 4:7], axis=1) > 0.005).sum())
    assert result["motion"]["steps"] == moved >= 10, (result, moved)  # a scripted push moves the puck
    assert -1.0 <= result["motion"]["cosine_median"] <= 1.0 and result["motion"]["length_ratio_median"] >= 0.0
    planner = result["planner"]
    assert planner["states"] >= 1 and planner["best_push"] + planner["best_hold"] + planner["best_own_plan"] == planner["states"], planner

    point = write(tmp_path, total_steps=400)  # the point-mass task: no object, no `goal - object`
    train(point, run_dir=tmp_path / "point", progress=False)
    monkeypatch.setattr("sys.argv", ["mpc_push_probe.py", str(tmp_path / "point/final.pt")])
    with pytest.raises(SystemExit, match="observation.relative_positions: true"):
        mpc_push_probe.main()
    monkeypatch.setattr("sys.argv", ["mpc_push_probe.py", str(tmp_path / "results")])  # a folder with no run in it
    with pytest.raises(SystemExit, match="no final.pt or checkpoint.pt"):
        mpc_push_probe.main()


def test_the_data_probe_counts_the_steps_a_scripted_pick_lifts_the_puck(tmp_path, monkeypatch):
    """The probe's lift count on a real pick run warm-started from one scripted pick of
    Meta-World's puck: the demo lifts it (measured: 11 steps of more than 5 mm), with the hand
    at the puck in most of its steps; the untrained planner's 400 steps after it do not. Its
    episode table finds the demo's one episode in the first window, whole, the hand at the puck
    and the puck lifted, and the planner's four envs' unfinished episodes (100 steps each) in
    the next, none of them lifting it."""
    checkpoint, transitions = demos_run(tmp_path, "tasks/metaworld/pick_place.yaml", "pick", episodes=1, planned_steps=400)
    result = probe_windows(tmp_path, monkeypatch, checkpoint, transitions)
    expert, *planned = result["windows"]
    assert expert["rose"] >= 5 and expert["at_object"] >= 0.5 * transitions, expert
    assert sum(row["rose"] for row in planned) <= 1, planned  # measured: 0
    demo, *own = result["episodes"]
    assert (demo["episodes"], demo["reached"], demo["lifted"]) == (1, 1, 1), demo
    assert sum(row["episodes"] for row in own) == 4 and sum(row["lifted"] for row in own) == 0, own

    before = np.arange(12.0).reshape(6, 2)  # two envs interleaved, three steps each
    after = before + 4.0  # each step's next observation begins the same env's next step
    after[2] = -1.0  # env 0's second step ended its episode: its next observation begins none
    chains = mpc_data_probe.episodes(before, after)
    assert [chain.tolist() for chain in chains] == [[0, 2], [1, 3, 5], [4]], chains


def test_the_model_probe_bins_the_whole_buffer_refits_it_and_plans_with_each_model(tmp_path, monkeypatch):
    """benchmarks/mpc_probe.py on a real pick run warm-started from one scripted pick: its motion
    table covers every transition of the buffer once; each refit (uniform, oversampled, β-NLL)
    learns the hand's motion, below predicting none, on the 10 % held out from it; each
    model then plans the held-out goal with the run's own search, in the order asked."""
    checkpoint, transitions = demos_run(tmp_path, "tasks/metaworld/pick_place.yaml", "pick", episodes=1, planned_steps=400)
    monkeypatch.setattr(benchmarks.common, "RESULTS", tmp_path / "results")
    monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(checkpoint.parent), "--trials", "1", "--refit", "1500",
                                     "--nll-beta", "0.5", "--no-bigger", "--out", "probe"])
    mpc_probe.main()
    result = json.loads((tmp_path / "results/probe.json").read_text())
    assert sum(row["transitions"] for row in result["object_motion"]) == transitions + 400, result["object_motion"]
    refits = ["refit, uniform", "refit, 50% moves >= 5 mm", "refit, uniform, beta-NLL 0.5"]
    errors = result["refit"]["errors"]
    assert list(errors) == ["run's model", *refits] and result["refit"]["run_nll_beta"] == 0.0, list(errors)
    for label in refits:
        rows = [row for row in errors[label] if row["transitions"]]
        assert sum(row["transitions"] for row in errors[label]) == result["refit"]["held_out"]
        learnt = sum(row["hand_error_mm"] * row["transitions"] for row in rows)
        still = sum(row["hand_no_motion_error_mm"] * row["transitions"] for row in rows)
        assert learnt < 0.85 * still, (label, rows)  # measured 0.56, 0.80, 0.56 of "no motion"
    assert [(row["model"], row["planner"]) for row in result["planners"]] == [("run's model", "as trained")] + [(label, "as trained") for label in refits]
    assert all(row["success_rate"] in (0.0, 1.0) for row in result["planners"]), result["planners"]


def test_the_model_probe_refits_the_value_and_the_narrowed_refit_reads_only_its_inputs(tmp_path, monkeypatch, capsys):
    """benchmarks/mpc_probe.py's value refits on a real pick run with a terminal value,
    warm-started from one scripted pick: the refit learns from the buffer's rewards (it values
    the demo's states, which earned the pick reward, above the untrained planner's); the one
    narrowed to `--value-inputs` gives the same value whatever the hand's x and y, the full
    one does not; each plans the held-out goal, after the run's own value and none. A run
    without a value is a one-line error, before any work. `--value-from` reads the value a
    checkpoint saved, not the one the agent holds. `--policy-value`'s TD3+BC Q values the demo's
    states above the planner's, and its pi acts nearer the data than doing nothing."""
    (tmp_path / "plain").mkdir()
    plain, _ = demos_run(tmp_path / "plain", "tasks/metaworld/pick_place.yaml", "pick", episodes=1, planned_steps=400)
    monkeypatch.setattr(benchmarks.common, "RESULTS", tmp_path / "results")
    monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(plain.parent), "--value-refit", "10"])
    with pytest.raises(SystemExit, match="need a run with mpc.terminal_value: true"):
        mpc_probe.main()

    checkpoint, transitions = demos_run(tmp_path, "tasks/metaworld/pick_place.yaml", "pick", episodes=1, planned_steps=400,
                                        terminal_value=True, discount=0.9)
    monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(checkpoint.parent), "--trials", "1", "--no-bigger",
                                     "--value-refit", "300", "--out", "probe"])
    mpc_probe.main()
    result = json.loads((tmp_path / "results/probe.json").read_text())
    narrowed = f"value refit, inputs {' '.join(map(str, mpc_probe.RELATIVE_INPUTS))}"
    assert [row["planner"] for row in result["planners"]] == ["as trained", "no terminal value", "value refit, all inputs", narrowed]
    assert result["value_refit"]["updates"] == 300 and set(result["value_refit"]["fits"]) == {"value refit, all inputs", narrowed}

    # `--value-heads` adds one fit of that many heads, planned at each pessimism; `--rows` fits
    # every value on the buffer's first rows; `--value-inputs` with no entries skips the narrowed
    # fit, `--no-value-all-inputs` the full one; `--value-discount` adds a fit at that discount,
    # planned with it (the run's own plans at 0.9)
    monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(checkpoint.parent), "--trials", "1", "--no-bigger", "--value-refit", "50",
                                     "--value-inputs", "--no-value-all-inputs", "--value-heads", "2", "--value-pessimism", "0", "1",
                                     "--heads-alone", "1", "--value-discount", "0.5", "--rows", "100", "--out", "heads"])
    mpc_probe.main()
    result = json.loads((tmp_path / "results/heads.json").read_text())
    assert [row["planner"] for row in result["planners"]][2:] == [
        "value refit, 2 heads, mean - 0 std", "value refit, 2 heads, mean - 1 std",
        "value refit, 2 heads: head 0 alone", "value refit, all inputs, discount 0.5"]
    assert [row["discount"] for row in result["planners"]] == [0.9] * 5 + [0.5], result["planners"]
    assert result["value_refit"]["rows"] == 100 and result["value_refit"]["fits"]["value refit, 2 heads"]["value_head_std"] > 0
    monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(checkpoint.parent), "--value-refit", "10", "--rows", "0"])
    with pytest.raises(SystemExit, match="--rows 0 must be in 1"):
        mpc_probe.main()

    # `--value-from` plans with the value another checkpoint saved, and with it fitted on for
    # `--value-from-updates`; `--no-own` skips the run's own value and none; a checkpoint without
    # a value, or no checkpoint, is a one-line error
    saved_at = checkpoint.parent / "checkpoint.pt"
    monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(checkpoint.parent), "--trials", "1", "--no-bigger", "--no-own",
                                     "--value-from", str(saved_at), "--value-from-updates", "20", "--out", "saved"])
    mpc_probe.main()
    result = json.loads((tmp_path / "results/saved.json").read_text())
    (source,) = result["value_from"]
    assert (source["checkpoint"], source["step"], source["value_refits"]) == (str(saved_at), result["step"], 0), source
    assert source["fit"]["value_loss"] >= 0, source
    label = f"value saved at step {result['step']:,}"
    assert [row["planner"] for row in result["planners"]] == [label, f"{label}, + 20 TD steps"]
    # `--policy-value` plans with TD3+BC's Q(s, pi(s)), alone and with pi's rollouts proposed
    monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(checkpoint.parent), "--trials", "1", "--no-bigger", "--no-own",
                                     "--policy-value", "20", "--out", "policy"])
    mpc_probe.main()
    result = json.loads((tmp_path / "results/policy.json").read_text())
    policy = "Q(s, pi(s)), TD3+BC 20 steps"
    assert [row["planner"] for row in result["planners"]] == [f"{policy}: pi alone, no search", policy, f"{policy}, 5 of pi's rollouts proposed"]
    assert [row["model"] for row in result["planners"]] == ["no model", "run's model", "run's model"]
    assert set(result["policy_value"]["fit"]) == {"value_loss", "policy_loss", "value_mean"}, result["policy_value"]
    for path, error in ((plain.parent / "checkpoint.pt", "this checkpoint has no terminal value"), (tmp_path / "none.pt", "expects a checkpoint.pt file")):
        monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(checkpoint.parent), "--trials", "0", "--value-from", str(path)])
        with pytest.raises(SystemExit, match=error):
            mpc_probe.main()
    monkeypatch.setattr("sys.argv", ["mpc_probe.py", str(checkpoint.parent), "--value-from-updates", "20"])
    with pytest.raises(SystemExit) as usage:  # argparse's usage error names what is missing
        mpc_probe.main()
    assert usage.value.code == 2 and "--value-from-updates needs --value-from" in capsys.readouterr().err

    agent = load_run(checkpoint).agent
    agent.load_state_dict(load_checkpoint(saved_at)["agent"])
    obs = agent.buffer.obs[: agent.buffer.size]
    own, agent.value = agent.value, mpc_probe.refit_value(agent, 10, seed=1)[0]  # the agent now holds another value
    saved_label, saved, _ = mpc_probe.saved_value(agent, saved_at)
    continued, _ = mpc_probe.refit_value(agent, 1, seed=0, start=saved)
    with torch.no_grad():  # the checkpoint's value, its input statistics with it, not the one the agent holds
        torch.testing.assert_close(saved(obs), own(obs))
        assert not torch.allclose(agent.value(obs), own(obs))
        # fitting on from it starts at its weights and leaves it as it was
        assert (continued(obs) - own(obs)).abs().mean() < 0.5 * (agent.value(obs) - own(obs)).abs().mean()  # measured 0.13
        torch.testing.assert_close(saved(obs), own(obs))
    assert saved_label == label
    agent.value = own
    moved = obs.clone()
    moved[:, :2] += 0.05  # the hand 5 cm along x and y, all else as it was
    (near, _), (far, _) = (mpc_probe.refit_value(agent, 300, seed=0, discount=gamma) for gamma in (0.5, None))
    with torch.no_grad():  # a value of a lower discount sums fewer of the same (positive) rewards
        assert (near.discount, far.discount) == (0.5, 0.9) and near(obs).mean() < far(obs).mean(), (near(obs).mean(), far(obs).mean())
    # TD3+BC's Q values the demo's states (which earned the pick reward) above the planner's, and
    # its pi acts in the planner's [-1, 1] nearer the data's actions than doing nothing does
    policy_value, _ = mpc_probe.fit_policy_value(agent, 300, seed=0)
    unit = 2.0 * (agent.buffer.actions[: agent.buffer.size] - agent.low) / (agent.high - agent.low) - 1.0
    with torch.no_grad():
        assert policy_value(obs[:transitions]).mean() > policy_value(obs[transitions:]).mean()
        chosen = policy_value.policy(obs)
        assert chosen.abs().max() <= 1 and ((chosen - unit) ** 2).mean() < (unit**2).mean(), (chosen - unit).pow(2).mean()
    for inputs in (None, mpc_probe.RELATIVE_INPUTS):
        value, _ = mpc_probe.refit_value(agent, 300, seed=0, inputs=inputs)
        with torch.no_grad():
            demo, own = value(obs[:transitions]).mean(), value(obs[transitions:]).mean()
            shift = (value(moved) - value(obs)).abs().max()
        assert demo > own, (inputs, demo, own)
        assert (shift == 0) if inputs else (shift > 0), (inputs, shift)


def test_optimism_plans_toward_what_the_model_has_not_seen_and_pessimism_away_from_it(tmp_path):
    """A model fitted only on actions that move left (x velocity <= 0), every reward 0: its
    members agree on the left and disagree on the right. With `optimism` the planner's first
    actions go right, into what the data lacks; with pessimism they stay left. (The members' mean
    alone happens to lean right here too, 0.47 measured, so optimism is compared with pessimism.)
    Without a second particle there is no spread to weigh: a one-line error."""
    rng = np.random.default_rng(0)
    obs = np.zeros((1000, 4), dtype=np.float32)
    actions = rng.uniform(-1.0, 1.0, (1000, 2)).astype(np.float32)
    actions[:, 0] = -np.abs(actions[:, 0])
    for t in range(1, 1000):  # episodes of 50 steps from the origin, moving 5 cm per unit action
        obs[t] = 0.0 if t % 50 == 0 else obs[t - 1] + np.r_[0.05 * actions[t - 1], 0.0, 0.0]
    space, action_space = Box(-np.inf, np.inf, (4,), np.float32), Box(-1.0, 1.0, (2,), np.float32)
    first = {}
    for optimism in (2.0, -2.0):
        (tmp_path / "agent.yaml").write_text(yaml.safe_dump({**AGENT, "mpc": {**AGENT["mpc"], "optimism": optimism}}))
        agent = MPCAgent(load_agent_spec(tmp_path / "agent.yaml"), space, action_space, seed=0)
        agent.add_demonstrations(obs, actions, np.zeros(1000, dtype=np.float32), np.arange(1000) % 50 == 0, "reach")
        agent.update()
        first[optimism] = agent.act(np.zeros((16, 4), dtype=np.float32), deterministic=True)[0][:, 0].mean()
    assert first[2.0] > 0.3 and first[-2.0] < -0.2, first  # measured 0.49 and -0.28
    with pytest.raises(ValueError, match="'optimism' .* needs 'particles' >= 2"):
        MPCSpec(optimism=1.0, ensemble_size=1, particles=1)
