"""Actor-critic networks: separate actor and critic bodies, MLP, LSTM or GRU, Gaussian actions.

The actor and the critic never share weights (core detail #13, continuous detail #4): value
gradients would otherwise shape the actor's features (and memory), which hurts continuous control
(Andrychowicz et al., 2021), and an asymmetric critic reads inputs the actor must not see.

Every method takes inputs shaped `[T, N, features]` (T steps of N env sequences): a rollout
step is `T = 1`, a recurrent minibatch is `T = bptt_length`, and a feed-forward minibatch is
`[1, batch, features]`, so one code path serves all three.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import gymnasium
import torch
from torch import nn
from torch.distributions import Normal

from taskforge.agents.actions import ClipGaussian, GaussianActions, SquashGaussian, sample_normal
from taskforge.spec.agent import PolicySpec

ACTIVATIONS: dict[str, type[nn.Module]] = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU}

Hidden = tuple[torch.Tensor, ...]
"""A recurrent core's state: `(h, c)` for an LSTM, `(h,)` for a GRU; each `[1, num_envs, size]`."""


class RecurrentState(NamedTuple):
    """The recurrent state of the actor and of the critic."""

    actor: Hidden
    critic: Hidden

    def select(self, env_idx: torch.Tensor) -> RecurrentState:
        """The state of a subset of envs (minibatch sequences, truncation bootstraps)."""
        return RecurrentState(*(tuple(part[:, env_idx] for part in net) for net in self))

    @staticmethod
    def concat(states: list[RecurrentState]) -> RecurrentState:
        """Join states of disjoint env batches along the env axis (chunks of a rollout)."""
        return RecurrentState(
            *(tuple(torch.cat(parts, dim=1) for parts in zip(*nets)) for nets in zip(*states))
        )


def layer_init(layer: nn.Linear, std: float = math.sqrt(2.0), bias: float = 0.0) -> nn.Linear:
    """Orthogonal weights scaled by `std`, constant bias (core detail #2)."""
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, bias)
    return layer


def mlp(in_dim: int, hidden_sizes: list[int], activation: str) -> nn.Sequential:
    layers: list[nn.Module] = []
    for size in hidden_sizes:
        layers += [layer_init(nn.Linear(in_dim, size)), ACTIVATIONS[activation]()]
        in_dim = size
    return nn.Sequential(*layers)


class MLPTorso(nn.Module):
    """Feed-forward body: features at a step depend on that step's input only."""

    def __init__(self, in_dim: int, spec: PolicySpec) -> None:
        super().__init__()
        self.in_dim = in_dim
        self.net = mlp(in_dim, spec.hidden_sizes, spec.activation)
        self.out_dim = spec.hidden_sizes[-1]

    def initial_state(self, num_envs: int) -> None:
        return None

    def forward(self, x: torch.Tensor, state: None, episode_starts: torch.Tensor) -> tuple[torch.Tensor, None]:
        return self.net(x), state


class RecurrentTorso(nn.Module):
    """An LSTM or GRU over the input, then an MLP (as SB3's RecurrentPPO for vector
    observations); with `encoder_sizes`, an MLP encodes the input before the core (as
    Meta-World+'s RL²). RL² uses the GRU (Duan et al., 2016).

    The hidden state is zeroed wherever an episode starts, both when acting and when re-running
    sequences in the update (LSTM details #3 and #5); otherwise the update would see a different
    state from the one the action was sampled with. Between two time steps at which some env
    starts an episode, the core runs over the whole segment in one call (PyTorch's own loop), so
    a long BPTT sequence costs one call per episode start rather than one per step. For RL²
    "episode" means trial: the env wrapper reports only trial starts.
    """

    def __init__(self, in_dim: int, spec: PolicySpec) -> None:
        super().__init__()
        self.in_dim = in_dim
        self.encoder = mlp(in_dim, spec.encoder_sizes, spec.activation)  # empty: the identity
        core = nn.LSTM if spec.type == "lstm" else nn.GRU
        self.core = core(spec.encoder_sizes[-1] if spec.encoder_sizes else in_dim, spec.recurrent_size)
        for name, param in self.core.named_parameters():  # LSTM detail #1: orthogonal weights, zero biases
            if "bias" in name:
                nn.init.constant_(param, 0.0)
            else:
                nn.init.orthogonal_(param, 1.0)
        self.net = mlp(spec.recurrent_size, spec.hidden_sizes, spec.activation)  # empty: the identity
        self.out_dim = spec.hidden_sizes[-1] if spec.hidden_sizes else spec.recurrent_size
        self._parts = 2 if spec.type == "lstm" else 1  # LSTM: (h, c); GRU: (h,)

    def initial_state(self, num_envs: int) -> Hidden:
        size = (1, num_envs, self.core.hidden_size)  # LSTM detail #2: the state starts at zero
        return tuple(torch.zeros(size) for _ in range(self._parts))

    def forward(self, x: torch.Tensor, state: Hidden, episode_starts: torch.Tensor) -> tuple[torch.Tensor, Hidden]:
        x = self.encoder(x)  # per step: no state in it
        starts = torch.nonzero(episode_starts.any(dim=1)).flatten().tolist()
        bounds = sorted({0, *starts, x.shape[0]})
        outputs = []
        for begin, end in zip(bounds[:-1], bounds[1:]):
            keep = (~episode_starts[begin]).float().view(1, -1, 1)  # LSTM detail #3: zero the state where an episode starts
            state = tuple(part * keep for part in state)
            out, state = self.core(x[begin:end], state if self._parts == 2 else state[0])
            state = state if self._parts == 2 else (state,)
            outputs.append(out)
        return self.net(torch.cat(outputs)), state


def make_torso(spec: PolicySpec, in_dim: int) -> MLPTorso | RecurrentTorso:
    return MLPTorso(in_dim, spec) if spec.type == "mlp" else RecurrentTorso(in_dim, spec)


class ActorCritic(nn.Module):
    """Gaussian actor on `obs`, value critic on `critic_obs` (`obs`, or `concat(obs, privileged)`
    for an asymmetric critic), each with its own torso.

    Outputs of the heads are initialised small (actor 0.01: initial actions near the mean with
    roughly equal probability in every direction; critic 1.0), as CleanRL.
    """

    def __init__(self, spec: PolicySpec, obs_dim: int, critic_dim: int, action_space: gymnasium.spaces.Box) -> None:
        super().__init__()
        action_dim = action_space.shape[0]
        self.actor = make_torso(spec, obs_dim)
        self.actor_mean = layer_init(nn.Linear(self.actor.out_dim, action_dim), std=0.01)
        self.actor_logstd = nn.Parameter(torch.full((action_dim,), spec.init_log_std))  # continuous detail #2
        self.critic = make_torso(spec, critic_dim)
        self.critic_value = layer_init(nn.Linear(self.critic.out_dim, 1), std=1.0)
        low = torch.as_tensor(action_space.low, dtype=torch.float32)
        high = torch.as_tensor(action_space.high, dtype=torch.float32)
        self.actions: GaussianActions = (
            SquashGaussian(low, high) if spec.action_bounds == "squash" else ClipGaussian(low, high)
        )

    @property
    def recurrent(self) -> bool:
        return isinstance(self.actor, RecurrentTorso)

    def initial_state(self, num_envs: int) -> RecurrentState | None:
        if not self.recurrent:
            return None
        return RecurrentState(self.actor.initial_state(num_envs), self.critic.initial_state(num_envs))

    def distribution(
        self, obs: torch.Tensor, state: RecurrentState | None, episode_starts: torch.Tensor
    ) -> tuple[Normal, Hidden | None]:
        features, actor_state = self.actor(obs, None if state is None else state.actor, episode_starts)
        mean = self.actor_mean(features)
        return Normal(mean, self.actor_logstd.exp().expand_as(mean), validate_args=False), actor_state

    def value(
        self, critic_obs: torch.Tensor, state: RecurrentState | None, episode_starts: torch.Tensor
    ) -> tuple[torch.Tensor, Hidden | None]:
        features, critic_state = self.critic(critic_obs, None if state is None else state.critic, episode_starts)
        return self.critic_value(features).squeeze(-1), critic_state

    def step(
        self,
        obs: torch.Tensor,
        critic_obs: torch.Tensor,
        state: RecurrentState | None,
        episode_starts: torch.Tensor,
        generator: torch.Generator,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, RecurrentState | None]:
        """Rollout step: raw action, its log-prob, the value, and the advanced state."""
        dist, actor_state = self.distribution(obs, state, episode_starts)
        value, critic_state = self.value(critic_obs, state, episode_starts)
        raw = sample_normal(dist, generator)
        new_state = None if actor_state is None else RecurrentState(actor_state, critic_state)
        return raw, self.actions.log_prob(dist, raw), value, new_state

    def evaluate(
        self,
        obs: torch.Tensor,
        critic_obs: torch.Tensor,
        raw_actions: torch.Tensor,
        state: RecurrentState | None,
        episode_starts: torch.Tensor,
        generator: torch.Generator,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Update step: log-prob of the stored raw actions, entropy and value under the current
        weights, re-running sequences from the rollout's initial state (LSTM detail #5)."""
        dist, _ = self.distribution(obs, state, episode_starts)
        value, _ = self.value(critic_obs, state, episode_starts)
        return self.actions.log_prob(dist, raw_actions), self.actions.entropy(dist, generator), value

    def act(
        self,
        obs: torch.Tensor,
        state: RecurrentState | None,
        episode_starts: torch.Tensor,
        deterministic: bool,
        generator: torch.Generator,
    ) -> tuple[torch.Tensor, RecurrentState | None]:
        """Evaluation: env-ready actions (the mean's image when deterministic). Only the actor
        runs; the critic part of the state is passed through untouched."""
        dist, actor_state = self.distribution(obs, state, episode_starts)
        raw = dist.mean if deterministic else sample_normal(dist, generator)
        new_state = None if state is None else RecurrentState(actor_state, state.critic)
        return self.actions.to_env(raw), new_state
