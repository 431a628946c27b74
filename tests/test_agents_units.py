"""Unit tests of taskforge.agents' parts: GAE, normalisers, action bounds, LSTM resets, minibatches.

Fast (milliseconds to a couple of seconds each) and env-free except where gymnasium's own
wrappers serve as the reference.
"""

from __future__ import annotations

import math
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
import torch
from torch.distributions import Normal

from taskforge.agents import (
    ObservationNormalizer,
    PPOAgent,
    RecurrentState,
    RewardScaler,
    RolloutBuffer,
    RunningMeanStd,
    SquashGaussian,
    compute_gae,
    set_torch_threads,
)
from taskforge.agents.policies import ActorCritic, RecurrentTorso
from taskforge.spec.agent import AgentSpec, PolicySpec

OBS_SPACE = gymnasium.spaces.Box(-np.inf, np.inf, shape=(3,), dtype=np.float32)
# Asymmetric bounds on purpose: squashing must rescale, not just tanh.
ACTION_SPACE = gymnasium.spaces.Box(np.array([-2.0, 0.0], dtype=np.float32), np.array([1.0, 5.0], dtype=np.float32))


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def agent_spec(**sections) -> AgentSpec:
    return AgentSpec.model_validate({"name": "test", **sections})


# --------------------------------------------------------------------------------------------- GAE

# One env, five steps, gamma 0.9, lambda 0.8: truncated at t=1 (final obs worth 10), terminated at t=3.
REWARDS = [1.0, 2.0, 3.0, 4.0, 5.0]
VALUES = [0.5, 1.0, 1.5, 2.0, 2.5]
TERMINATED = [False, False, False, True, False]
TRUNCATED = [False, True, False, False, False]
FINAL_VALUE_AT_TRUNCATION = 10.0
LAST_VALUE = 3.0  # V of the observation after the rollout
# By hand (gl = gamma * lambda = 0.72):
#   t4: delta = 5 + 0.9*3.0 - 2.5 = 5.2                      A4 = 5.2
#   t3: terminated, no bootstrap: delta = 4 - 2.0 = 2.0      A3 = 2.0 (trace cut)
#   t2: delta = 3 + 0.9*2.0 - 1.5 = 3.3                      A2 = 3.3 + 0.72*2.0 = 4.74
#   t1: truncated, bootstrap from the final obs:
#       delta = 2 + 0.9*10.0 - 1.0 = 10.0                    A1 = 10.0 (trace cut)
#   t0: delta = 1 + 0.9*1.0 - 0.5 = 1.4                      A0 = 1.4 + 0.72*10.0 = 8.6
EXPECTED_ADVANTAGES = [8.6, 10.0, 4.74, 2.0, 5.2]
EXPECTED_RETURNS = [9.1, 11.0, 6.24, 4.0, 7.7]


def column(values, dtype=torch.float32) -> torch.Tensor:
    return torch.tensor(values, dtype=dtype).unsqueeze(1)  # [T, N=1]


def test_gae_matches_hand_computed_example_with_truncation_and_termination():
    next_values = column([VALUES[1], FINAL_VALUE_AT_TRUNCATION, VALUES[3], 99.0, LAST_VALUE])  # 99: ignored
    advantages, returns = compute_gae(
        column(REWARDS),
        column(VALUES),
        next_values,
        column(TERMINATED, torch.bool),
        column(TRUNCATED, torch.bool),
        gamma=0.9,
        lam=0.8,
    )
    torch.testing.assert_close(advantages, column(EXPECTED_ADVANTAGES))
    torch.testing.assert_close(returns, column(EXPECTED_RETURNS))


def test_rollout_buffer_builds_next_values_from_final_values_on_truncation():
    buffer = RolloutBuffer(num_steps=5, num_envs=1, obs_dim=1, critic_dim=1, action_dim=1)
    buffer.rewards = column(REWARDS)
    buffer.values = column(VALUES)
    buffer.terminated = column(TERMINATED, torch.bool)
    buffer.truncated = column(TRUNCATED, torch.bool)
    buffer.final_values = column([0.0, FINAL_VALUE_AT_TRUNCATION, 0.0, 0.0, 0.0])
    buffer.compute_advantages(torch.tensor([LAST_VALUE]), gamma=0.9, lam=0.8)
    torch.testing.assert_close(buffer.advantages, column(EXPECTED_ADVANTAGES))
    torch.testing.assert_close(buffer.returns, column(EXPECTED_RETURNS))


def test_gae_without_episode_ends_is_the_lambda_return():
    rng = np.random.default_rng(0)
    rewards, values, last = rng.normal(size=6), rng.normal(size=6), rng.normal()
    gamma, lam = 0.97, 0.9
    next_values = np.append(values[1:], last)
    deltas = rewards + gamma * next_values - values
    expected = [sum((gamma * lam) ** k * deltas[t + k] for k in range(6 - t)) for t in range(6)]
    no_end = column([False] * 6, torch.bool)
    advantages, _ = compute_gae(
        column(rewards, torch.float64), column(values, torch.float64), column(next_values, torch.float64),
        no_end, no_end, gamma, lam,
    )
    np.testing.assert_allclose(advantages[:, 0].numpy(), expected, rtol=1e-10)


# ---------------------------------------------------------------------------------- normalisation

def test_running_mean_std_parallel_update_matches_whole_data():
    rng = np.random.default_rng(0)
    batches = [rng.normal(3.0, 2.0, size=(n, 4)) for n in (1, 7, 50, 3)]
    rms = RunningMeanStd((4,), epsilon=1e-12)
    for batch in batches:
        rms.update(torch.as_tensor(batch))
    data = np.concatenate(batches)
    np.testing.assert_allclose(rms.mean.numpy(), data.mean(0), rtol=1e-8)
    np.testing.assert_allclose(rms.var.numpy(), data.var(0), rtol=1e-8)


def test_observation_normalizer_clips_at_ten_and_freezes_without_update():
    normalizer = ObservationNormalizer(2, enabled=True)
    normalizer(np.random.default_rng(0).normal(size=(100, 2)), update=True)
    frozen = normalizer.rms.state_dict()
    out = normalizer(np.array([[1e6, -1e6]]), update=False)
    assert out.tolist() == [[10.0, -10.0]]
    assert all(torch.equal(frozen[k], v) for k, v in normalizer.rms.state_dict().items())


def test_reward_scaler_matches_gymnasium_normalize_reward_under_same_step_autoreset():
    """Same reward stream (random Pendulum actions, 5-step episodes) through gymnasium's vector
    NormalizeReward and through ours (clipping disabled: it is the only intended difference)."""

    def make_envs():
        fns = [lambda: gymnasium.make("Pendulum-v1", max_episode_steps=5) for _ in range(3)]
        return gymnasium.vector.SyncVectorEnv(fns, autoreset_mode=gymnasium.vector.AutoresetMode.SAME_STEP)

    raw_envs = make_envs()
    reference = gymnasium.wrappers.vector.NormalizeReward(make_envs(), gamma=0.9)
    raw_envs.reset(seed=0)
    reference.reset(seed=0)
    scaler = RewardScaler(num_envs=3, gamma=0.9, enabled=True, clip=math.inf)
    actions = np.random.default_rng(0).uniform(-2, 2, size=(23, 3, 1)).astype(np.float32)
    for action in actions:
        _, reward, terminated, truncated, _ = raw_envs.step(action)
        _, expected, *_ = reference.step(action)
        np.testing.assert_allclose(scaler(reward, terminated, truncated).numpy(), expected, rtol=1e-4)


# -------------------------------------------------------------------------------- action bounds

@pytest.mark.parametrize("bounds", ["clip", "squash"])
def test_actions_are_always_inside_the_box(bounds):
    spec = agent_spec(policy={"action_bounds": bounds, "init_log_std": 2.0, "hidden_sizes": [16]})
    agent = PPOAgent(spec, OBS_SPACE, ACTION_SPACE, seed=0)
    obs = np.random.default_rng(0).normal(scale=5.0, size=(2000, 3)).astype(np.float32)
    for deterministic in (True, False):
        actions, _ = agent.act(obs, deterministic=deterministic)
        assert actions.shape == (2000, 2) and actions.dtype == np.float32
        assert (actions >= ACTION_SPACE.low).all() and (actions <= ACTION_SPACE.high).all()


def test_clip_mode_stores_and_scores_the_unclipped_sample():
    """CleanRL: the log-prob is that of the raw Gaussian sample; only the env sees it clipped."""
    spec = agent_spec(policy={"action_bounds": "clip", "init_log_std": 2.0, "hidden_sizes": [16]})
    agent = PPOAgent(spec, OBS_SPACE, ACTION_SPACE, seed=0)
    obs = torch.randn(1, 500, 3)
    with torch.no_grad():
        raw, logprob, _, _ = agent.policy.step(obs, obs, None, torch.zeros(1, 500, dtype=torch.bool), agent.generator)
        dist, _ = agent.policy.distribution(obs, None, torch.zeros(1, 500, dtype=torch.bool))
    low, high = torch.as_tensor(ACTION_SPACE.low), torch.as_tensor(ACTION_SPACE.high)
    assert ((raw < low) | (raw > high)).any()  # std e^2: many samples leave the box
    torch.testing.assert_close(logprob, dist.log_prob(raw).sum(-1))
    torch.testing.assert_close(agent.policy.actions.to_env(raw), torch.maximum(torch.minimum(raw, high), low))


def test_squash_log_prob_matches_numerical_change_of_variables():
    """log p(a) from the tanh correction equals the log of a finite-difference density: the
    probability that `a` falls in [a - h, a + h], from the Gaussian CDF at atanh of the ends."""
    low, high = torch.tensor([-2.0, 0.0], dtype=torch.float64), torch.tensor([1.0, 5.0], dtype=torch.float64)
    squash = SquashGaussian(low, high)
    dist = Normal(torch.tensor([0.3, -0.8], dtype=torch.float64), torch.tensor([0.7, 1.3], dtype=torch.float64))
    h = 1e-6
    for raw in torch.tensor([[0.0, 0.0], [1.2, -0.4], [-2.5, 1.9], [0.05, -3.0]], dtype=torch.float64):
        action = squash.to_env(raw)

        def raw_of(a: torch.Tensor) -> torch.Tensor:
            return torch.atanh((a - squash.center) / squash.scale)

        per_dim_density = (dist.cdf(raw_of(action + h)) - dist.cdf(raw_of(action - h))) / (2 * h)
        numerical = torch.log(per_dim_density).sum()
        torch.testing.assert_close(squash.log_prob(dist, raw), numerical, rtol=1e-5, atol=1e-5)


def test_squash_needs_a_finite_box():
    unbounded = gymnasium.spaces.Box(-np.inf, np.inf, shape=(2,), dtype=np.float32)
    with pytest.raises(ValueError, match="finite action Box"):
        PPOAgent(agent_spec(policy={"action_bounds": "squash"}), OBS_SPACE, unbounded)


# ------------------------------------------------------------------------------------------ LSTM

def lstm_policy() -> ActorCritic:
    torch.manual_seed(0)
    spec = PolicySpec(type="lstm", hidden_sizes=[16], recurrent_size=8)
    return ActorCritic(spec, obs_dim=3, critic_dim=3, action_space=ACTION_SPACE)


def test_lstm_state_is_reset_where_an_episode_starts():
    """Acting on an obs sequence after other steps, with episode_start on its first step, gives
    exactly what the same sequence gives from a fresh state."""
    agent = PPOAgent(
        agent_spec(policy={"type": "lstm", "hidden_sizes": [16], "recurrent_size": 8}, ppo={"num_minibatches": 4}),
        OBS_SPACE,
        ACTION_SPACE,
    )
    rng = np.random.default_rng(0)
    history, sequence = rng.normal(size=(5, 2, 3)), rng.normal(size=(6, 2, 3))

    state = agent.initial_state(2)
    for obs in history:  # build up a non-zero state
        _, state = agent.act(obs, state)
    assert state.actor[0].abs().sum() > 0

    fresh_state = agent.initial_state(2)
    for t, obs in enumerate(sequence):
        # env 0 starts a new episode at t=0, env 1 does not
        after_reset, state = agent.act(obs, state, episode_start=np.array([t == 0, False]))
        from_fresh, fresh_state = agent.act(obs, fresh_state)
        np.testing.assert_array_equal(after_reset[0], from_fresh[0])
        assert not np.array_equal(after_reset[1], from_fresh[1])


def test_lstm_sequence_evaluation_resets_at_episode_starts_inside_the_sequence():
    """The update re-runs whole sequences: a start flag at step k must make steps k.. identical
    to evaluating them from a zero state."""
    policy = lstm_policy()
    T, k = 8, 3
    obs = torch.randn(T, 2, 3)
    actions = torch.randn(T, 2, 2)
    starts = torch.zeros(T, 2, dtype=torch.bool)
    starts[k, 0] = True
    state = RecurrentState((torch.randn(1, 2, 8), torch.randn(1, 2, 8)), (torch.randn(1, 2, 8), torch.randn(1, 2, 8)))
    generator = torch.Generator().manual_seed(0)
    with torch.no_grad():
        logprob, _, value = policy.evaluate(obs, obs, actions, state, starts, generator)
        fresh, no_starts = policy.initial_state(1), torch.zeros(T - k, 1, dtype=torch.bool)
        suffix_logprob, _, suffix_value = policy.evaluate(
            obs[k:, :1], obs[k:, :1], actions[k:, :1], fresh, no_starts, generator
        )
    torch.testing.assert_close(logprob[k:, :1], suffix_logprob, rtol=0, atol=1e-6)
    torch.testing.assert_close(value[k:, :1], suffix_value, rtol=0, atol=1e-6)


@pytest.mark.parametrize("core,encoder,hidden", [("lstm", [], [16]), ("gru", [], [16]), ("gru", [5, 6], [16]), ("gru", [5], [])])
def test_recurrent_torso_runs_segments_exactly_as_stepping_one_step_at_a_time(core, encoder, hidden):
    """The torso runs the core over whole segments between episode starts; the reference is the
    plain per-step loop that zeroes the state wherever an env starts (starts at t=0, mid-sequence,
    in one env only, in both, and on the last step). With `encoder_sizes` the core reads the
    encoder's features of each step; with no `hidden_sizes` the torso's output is the core's."""
    torch.manual_seed(0)
    torso = RecurrentTorso(3, PolicySpec(type=core, hidden_sizes=hidden, recurrent_size=8, encoder_sizes=encoder))
    assert torso.out_dim == (hidden[-1] if hidden else 8)
    assert len([m for m in torso.encoder if isinstance(m, torch.nn.Linear)]) == len(encoder)
    T, N = 12, 3
    x = torch.randn(T, N, 3)
    starts = torch.zeros(T, N, dtype=torch.bool)
    starts[0, 1] = starts[4, 0] = starts[4, 2] = starts[7, 1] = starts[T - 1, 0] = True
    state = tuple(torch.randn(1, N, 8) for _ in range(2 if core == "lstm" else 1))

    expected, ref_state = [], state
    for x_t, start_t in zip(x, starts):
        ref_state = tuple(part * (~start_t).float().view(1, -1, 1) for part in ref_state)
        out, ref_state = torso.core(torso.encoder(x_t.unsqueeze(0)), ref_state if core == "lstm" else ref_state[0])
        ref_state = ref_state if core == "lstm" else (ref_state,)
        expected.append(out)
    with torch.no_grad():
        features, final_state = torso(x, state, starts)
        torch.testing.assert_close(features, torso.net(torch.cat(expected)), rtol=0, atol=1e-6)
        for part, ref_part in zip(final_state, ref_state):
            torch.testing.assert_close(part, ref_part, rtol=0, atol=1e-6)


@pytest.mark.parametrize("chunk_length", [None, 4])
def test_sequence_minibatches_keep_whole_chunks_with_the_state_they_started_from(chunk_length):
    T, N = 8, 6
    L = chunk_length or T
    buffer = RolloutBuffer(num_steps=T, num_envs=N, obs_dim=2, critic_dim=2, action_dim=1, chunk_length=chunk_length)
    steps, envs = torch.meshgrid(torch.arange(T), torch.arange(N), indexing="ij")
    buffer.obs = torch.stack([steps, envs], dim=-1).float()  # obs[t, e] = (t, e)
    buffer.returns = envs.float()
    for t in range(T):  # the state recorded before step t marks (t, env)
        marker = (1000 * t + torch.arange(N)).float().view(1, N, 1).expand(1, N, 4)
        buffer.record_state(t, RecurrentState((marker, marker + 100), (marker + 200, marker + 300)))
    assert len(buffer.chunk_states) == T // L

    seen: list[tuple[int, int]] = []
    for mb in buffer.minibatches(3, torch.Generator().manual_seed(0), recurrent=True):
        assert mb.obs.shape[0] == L
        for j in range(mb.obs.shape[1]):
            start, env = int(mb.obs[0, j, 0]), int(mb.obs[0, j, 1])
            assert mb.obs[:, j, 0].tolist() == list(range(start, start + L))  # every step of the chunk, in order
            assert (mb.obs[:, j, 1] == env).all() and (mb.returns[:, j] == env).all()
            assert mb.state.actor[0][0, j, 0] == 1000 * start + env and mb.state.critic[1][0, j, 0] == 1000 * start + env + 300
            seen.append((start, env))
    assert sorted(seen) == [(c * L, e) for c in range(T // L) for e in range(N)]  # the minibatches partition the chunks

    flat_batches = buffer.minibatches(4, torch.Generator().manual_seed(0), recurrent=False)
    flat = [mb.obs.reshape(-1, 2) for mb in flat_batches]
    pairs = sorted(map(tuple, torch.cat(flat).int().tolist()))
    assert pairs == [(t, e) for t in range(T) for e in range(N)]  # flat minibatches: each step once


# ------------------------------------------------------------------------------- construction

@pytest.mark.parametrize("policy_type", ["mlp", "lstm", "gru"])
def test_asymmetric_critic_input_is_obs_plus_privileged_and_actor_input_is_obs(policy_type):
    spec = agent_spec(
        policy={"type": policy_type, "hidden_sizes": [16]}, ppo={"num_minibatches": 4}, asymmetric_critic=True
    )
    policy = PPOAgent(spec, OBS_SPACE, ACTION_SPACE, privileged_dim=5).policy
    def input_size(torso) -> int:
        return torso.net[0].in_features if policy_type == "mlp" else torso.core.input_size

    assert input_size(policy.actor) == policy.actor.in_dim == 3
    assert input_size(policy.critic) == policy.critic.in_dim == 3 + 5


def test_symmetric_spec_ignores_privileged_dim_and_asymmetric_spec_requires_it():
    assert PPOAgent(agent_spec(), OBS_SPACE, ACTION_SPACE, privileged_dim=5).policy.critic.net[0].in_features == 3
    with pytest.raises(ValueError, match="privileged_dim"):
        PPOAgent(agent_spec(asymmetric_critic=True), OBS_SPACE, ACTION_SPACE)


def test_set_progress_anneals_learning_rate_linearly():
    agent = PPOAgent(agent_spec(ppo={"learning_rate": 1e-3}), OBS_SPACE, ACTION_SPACE)
    agent.set_progress(0.25)
    assert agent.optimizer.param_groups[0]["lr"] == pytest.approx(7.5e-4)
    agent.set_progress(2.0)  # clamped
    assert agent.optimizer.param_groups[0]["lr"] == 0.0
    fixed = PPOAgent(agent_spec(ppo={"learning_rate": 1e-3, "anneal_lr": False}), OBS_SPACE, ACTION_SPACE)
    fixed.set_progress(0.5)
    assert fixed.optimizer.param_groups[0]["lr"] == 1e-3


def test_set_torch_threads_follows_the_runtime_spec():
    set_torch_threads(agent_spec(runtime={"torch_threads": 2}).runtime)
    assert torch.get_num_threads() == 2


FLUSH_PROBE = """
import torch
from taskforge.agents import set_torch_threads
from taskforge.spec.agent import RuntimeSpec
if {configure}:
    set_torch_threads(RuntimeSpec(torch_threads=2))
torch.set_num_threads(2)
tiny = torch.full((1 << 20,), 1e-39)  # denormal; the multiply below is split between both threads
print(int((tiny * 1.0 != 0).sum()))
"""


@pytest.mark.parametrize("configure", [True, False], ids=["set_torch_threads", "untouched"])
def test_set_torch_threads_flushes_denormals_in_every_thread_torch_starts(configure):
    """Denormal weights slow an Intel CPU's multiplies ~10x (`flush_denormals`). In a fresh process
    (the flag is per thread, inherited when torch starts its workers), a 2-thread multiply of
    denormals is all zeros after `set_torch_threads`; untouched, every element survives (the
    control: the probe sees the flag)."""
    probe = subprocess.run([sys.executable, "-c", FLUSH_PROBE.format(configure=configure)], capture_output=True, text=True, check=True)
    assert int(probe.stdout) == (0 if configure else 1 << 20)


def test_construction_is_seeded_and_leaves_the_global_rng_alone():
    torch.manual_seed(123)
    before = torch.get_rng_state()
    a = PPOAgent(agent_spec(), OBS_SPACE, ACTION_SPACE, seed=7)
    assert torch.equal(torch.get_rng_state(), before)
    b = PPOAgent(agent_spec(), OBS_SPACE, ACTION_SPACE, seed=7)
    c = PPOAgent(agent_spec(), OBS_SPACE, ACTION_SPACE, seed=8)
    pairs = list(zip(a.policy.parameters(), b.policy.parameters(), c.policy.parameters()))
    assert all(torch.equal(pa, pb) for pa, pb, _ in pairs)
    assert not all(torch.equal(pa, pc) for pa, _, pc in pairs)
