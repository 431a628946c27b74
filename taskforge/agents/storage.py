"""The rollout buffer: `[T, N]` tensors of one collection, and the minibatches PPO trains on."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import torch

from taskforge.agents.gae import compute_gae
from taskforge.agents.policies import RecurrentState

# Per-step fields a minibatch carries to the loss.
MINIBATCH_FIELDS = ("obs", "critic_obs", "actions", "logprobs", "values", "advantages", "returns", "episode_starts")


@dataclass(frozen=True)
class Minibatch:
    """Tensors shaped `[T, n, ...]`: `n` sequences of length `T = bptt_length` (recurrent
    policy), or `T = 1` and `n` shuffled single steps (feed-forward policy)."""

    obs: torch.Tensor
    critic_obs: torch.Tensor
    actions: torch.Tensor
    logprobs: torch.Tensor
    values: torch.Tensor
    advantages: torch.Tensor
    returns: torch.Tensor
    episode_starts: torch.Tensor
    state: RecurrentState | None
    """Recurrent state at the first step of each sequence (None for a feed-forward policy)."""


class RolloutBuffer:
    """Holds `num_steps` vector steps of `num_envs` envs.

    Observations are stored already normalised (as the policy saw them), actions raw (before
    clipping or squashing, continuous detail #5), rewards already scaled. A recurrent rollout is
    cut into chunks of `chunk_length` steps; `chunk_states[c]` is the recurrent state before the
    first step of chunk c, from which the update re-runs that chunk (truncated BPTT).
    """

    def __init__(
        self, num_steps: int, num_envs: int, obs_dim: int, critic_dim: int, action_dim: int, chunk_length: int | None = None
    ) -> None:
        self.num_steps = num_steps
        self.chunk_length = chunk_length or num_steps
        self.num_envs = num_envs
        shape = (num_steps, num_envs)
        self.obs = torch.zeros((*shape, obs_dim))
        self.critic_obs = torch.zeros((*shape, critic_dim))
        self.actions = torch.zeros((*shape, action_dim))
        self.logprobs = torch.zeros(shape)
        self.values = torch.zeros(shape)
        self.rewards = torch.zeros(shape)
        self.episode_starts = torch.zeros(shape, dtype=torch.bool)
        self.terminated = torch.zeros(shape, dtype=torch.bool)
        self.truncated = torch.zeros(shape, dtype=torch.bool)
        self.final_values = torch.zeros(shape)
        self.advantages = torch.zeros(shape)
        self.returns = torch.zeros(shape)
        self.chunk_states: list[RecurrentState] = []

    def record_state(self, t: int, state: RecurrentState | None) -> None:
        """Keep the recurrent state before step `t` if a chunk starts there (LSTM detail #5)."""
        if state is not None and t % self.chunk_length == 0:
            del self.chunk_states[t // self.chunk_length :]
            self.chunk_states.append(state)

    def store(
        self,
        t: int,
        *,
        obs: torch.Tensor,
        critic_obs: torch.Tensor,
        episode_starts: torch.Tensor,
        actions: torch.Tensor,
        logprobs: torch.Tensor,
        values: torch.Tensor,
        rewards: torch.Tensor,
        terminated: torch.Tensor,
        truncated: torch.Tensor,
        final_values: torch.Tensor,
    ) -> None:
        """Record vector step `t`; `final_values` is V(final obs) where `truncated`, else unused."""
        self.obs[t] = obs
        self.critic_obs[t] = critic_obs
        self.episode_starts[t] = episode_starts
        self.actions[t] = actions
        self.logprobs[t] = logprobs
        self.values[t] = values
        self.rewards[t] = rewards
        self.terminated[t] = terminated
        self.truncated[t] = truncated
        self.final_values[t] = final_values

    def compute_advantages(self, last_values: torch.Tensor, gamma: float, lam: float) -> None:
        """GAE over the buffer; `last_values` is V of the observation after the last step."""
        next_values = torch.cat([self.values[1:], last_values.unsqueeze(0)])
        # truncation bootstrap: the episode went on, from its final observation, not the reset one
        next_values = torch.where(self.truncated, self.final_values, next_values)
        self.advantages, self.returns = compute_gae(
            self.rewards, self.values, next_values, self.terminated, self.truncated, gamma, lam
        )

    def minibatches(self, num_minibatches: int, generator: torch.Generator, recurrent: bool) -> Iterator[Minibatch]:
        """One epoch of shuffled minibatches (core detail #6).

        Recurrent policy (LSTM detail #4): the `[T, N]` rollout becomes `N * T / chunk_length`
        sequences of `chunk_length` steps (chunk-major), shuffled whole, each with the state it
        started from, so the core is re-run exactly as it acted. Otherwise shuffle single steps.
        """
        if recurrent:
            chunks, length = self.num_steps // self.chunk_length, self.chunk_length
            source = {  # [T, N, ...] -> [chunks, length, N, ...] -> [length, chunks * N, ...]
                name: getattr(self, name).unflatten(0, (chunks, length)).transpose(0, 1).flatten(1, 2)
                for name in MINIBATCH_FIELDS
            }
            states = RecurrentState.concat(self.chunk_states)
            count = chunks * self.num_envs
        else:
            source = {name: getattr(self, name).flatten(0, 1).unsqueeze(0) for name in MINIBATCH_FIELDS}
            count = self.num_steps * self.num_envs
        permutation = torch.randperm(count, generator=generator)
        for idx in torch.tensor_split(permutation, num_minibatches):
            state = states.select(idx) if recurrent else None
            yield Minibatch(**{name: tensor[:, idx] for name, tensor in source.items()}, state=state)
