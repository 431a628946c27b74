"""Warm start from demonstrations: behaviour cloning of the actor and value regression of the
critic, before PPO fine-tunes (with the decaying BC term of `PPOAgent.set_demo_regularizer`,
after DAPG, Rajeswaran et al. 2018).

Choices, and why:

* **BC loss: mean squared error between the policy's mean action and the demo action**, not
  the log-likelihood. The Gaussian's log-std is state-independent and learnable; maximising the
  likelihood of (nearly deterministic) scripted actions drives it towards the demos' tiny
  residual, so PPO would start with almost no exploration, and the likelihood's gradient on the
  mean is scaled by 1/σ², which ties the effective learning rate to that collapsing σ. MSE
  trains the mean only and leaves the preset's `init_log_std`. The mean is compared in env
  units: as it is for `clip` (demo actions lie inside the box, so the unclipped mean is pulled
  inside too), through `tanh` for `squash`.
* **Observation normalisation**: the agent's normaliser is updated with the demo observations
  *before* pretraining, so the networks are fitted on exactly the input scale PPO will feed
  them; PPO's rollouts then keep updating the same statistics.
* **Value targets** are discounted returns-to-go of the demo rewards, in the units PPO's critic
  learns: the rewards go through the agent's reward scaler first (which also updates its
  statistics), then `gamma` discounts them. Episodes that ended by the time limit are
  bootstrapped as if their last reward went on (`r_T / (1 - gamma)`), matching PPO's own
  bootstrapping of truncation; terminated episodes end at zero.
* **Asymmetric critic**: it reads `concat(obs, privileged)`; demos recorded by `taskforge demos`
  carry `info["privileged"]` (zero-padded to the agent's width, like the env does). Without it,
  or with a wider vector than the agent's, the critic is not pretrained (PPO fits it as usual).
* **Recurrent (LSTM, GRU) policies** are cloned on whole demo episodes, each from a fresh state,
  as they will act (`agents/sequences.py`): a minibatch is about `batch_size` steps of whole
  episodes, and the losses are means over the real (unpadded) steps. The same rows serve the
  exploration fit and PPO's demonstration term.
"""

from __future__ import annotations

import sys

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from taskforge.agents.actions import SquashGaussian
from taskforge.agents.normalization import RewardScaler
from taskforge.agents.ppo import PPOAgent
from taskforge.agents.runtime import torch_threads, update_threads
from taskforge.agents.sequences import DemoRows, columns_per_batch, demo_rows


def returns_to_go(rewards: np.ndarray, episode_starts: np.ndarray, truncated: np.ndarray, gamma: float) -> np.ndarray:
    """Discounted returns-to-go of concatenated episodes; a truncated episode's tail is
    bootstrapped with `r_last / (1 - gamma)` (see the module doc)."""
    rewards = np.asarray(rewards, dtype=np.float64)
    out = np.zeros_like(rewards)
    running = 0.0
    for t in range(len(rewards) - 1, -1, -1):
        last = t == len(rewards) - 1 or episode_starts[t + 1]
        if last:
            running = rewards[t] / (1.0 - gamma) if truncated[t] else rewards[t]
        else:
            running = rewards[t] + gamma * running
        out[t] = running
    return out


def scaled_rewards(agent: PPOAgent, rewards: np.ndarray, episode_starts: np.ndarray, terminated: np.ndarray) -> np.ndarray:
    """The demo rewards as PPO's critic sees them. Each episode is fed through a reward scaler
    that shares the agent's statistics (so they now include the demos, as if collected), then
    all rewards are divided by the final scale."""
    scaler = agent.reward_scaler
    if not scaler.enabled:
        return np.asarray(rewards, dtype=np.float64)
    feeder = RewardScaler(1, scaler.gamma, True, scaler.clip, scaler.epsilon)
    feeder.rms = scaler.rms  # the same object: updates land in the agent's statistics
    ends = np.append(np.asarray(episode_starts[1:], dtype=bool), True)
    for r, end, term in zip(rewards, ends, terminated):
        feeder(np.array([r]), np.array([bool(term)]), np.array([bool(end and not term)]))
    scale = float(torch.sqrt(scaler.rms.var + scaler.epsilon))
    return np.clip(np.asarray(rewards, dtype=np.float64) / scale, -scaler.clip, scaler.clip)


def pretrain(
    agent: PPOAgent,
    observations: np.ndarray,
    actions: np.ndarray,
    returns_to_go: np.ndarray | None = None,
    epochs: int = 50,
    batch_size: int = 256,
    learning_rate: float = 1e-3,
    privileged: np.ndarray | None = None,
    update_normalizer: bool = True,
    progress: bool = False,
    episode_starts: np.ndarray | None = None,
) -> dict[str, float]:
    """Behaviour cloning of the actor (MSE of the mean action) and, given `returns_to_go` (in
    the critic's units, see `scaled_rewards`), value regression of the critic.

    Updates the agent's observation normaliser with `observations` first, unless
    `update_normalizer` is False (a DAgger refit on an aggregate whose older part the statistics
    already hold). Shuffles with the agent's generator, so a seed fixes the result. Returns
    `bc_action_mse_before/after` and, when the critic was trained, `bc_value_mse_before/after`,
    plus `bc_samples`, `bc_epochs`. `progress` shows a bar over the epochs (minutes on 2 cores).
    A recurrent policy needs `episode_starts` (where each demo episode begins; module doc).
    """
    obs = np.asarray(observations, dtype=np.float32)
    act = torch.as_tensor(np.asarray(actions, dtype=np.float32))
    if obs.ndim != 2 or obs.shape[1] != agent.obs_normalizer.rms.mean.shape[0]:
        raise ValueError(f"demo observations have shape {obs.shape}, the agent expects [n, {agent.obs_normalizer.rms.mean.shape[0]}]")
    if act.shape != (len(obs), agent.action_space.shape[0]):
        raise ValueError(f"demo actions have shape {tuple(act.shape)}, expected ({len(obs)}, {agent.action_space.shape[0]})")
    policy = agent.policy
    rows = _rows(agent, len(obs), episode_starts)
    obs_n = agent.obs_normalizer(obs, update=update_normalizer)  # PPO will see this scale too (module doc)
    critic_in = _critic_input(agent, obs_n, privileged) if returns_to_go is not None else None
    targets = None if critic_in is None else torch.as_tensor(np.asarray(returns_to_go), dtype=torch.float32)

    def action_error(batch: DemoRows) -> torch.Tensor:
        predicted = mean_actions(agent, obs_n, batch)
        return ((predicted - act[batch.index]) ** 2).mean(dim=-1)[batch.mask].mean()

    def value_error(batch: DemoRows) -> torch.Tensor:
        values, _ = policy.value(critic_in[batch.index], policy.initial_state(batch.width), batch.starts)
        return ((values - targets[batch.index]) ** 2)[batch.mask].mean()

    params = [p for name, p in policy.named_parameters() if name != "actor_logstd"]
    optimizer = torch.optim.Adam(params, lr=learning_rate, eps=1e-5)
    metrics: dict[str, float] = {"bc_samples": float(len(obs)), "bc_epochs": float(epochs)}
    per_batch = columns_per_batch(rows, batch_size)
    with torch_threads(update_threads(agent.spec.runtime)):
        with torch.no_grad():
            metrics["bc_action_mse_before"] = action_error(rows).item()
            if targets is not None:
                metrics["bc_value_mse_before"] = value_error(rows).item()
        for _ in tqdm(range(epochs), desc="behaviour cloning", unit="epoch", disable=not progress, leave=False,
                      file=sys.stderr, dynamic_ncols=True):
            for columns in torch.randperm(rows.width, generator=agent.generator).split(per_batch):
                batch = rows.take(columns)
                loss = action_error(batch)
                if targets is not None:
                    loss = loss + value_error(batch)  # separate networks: the sum trains each on its own loss
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(params, agent.spec.ppo.max_grad_norm)
                optimizer.step()
        with torch.no_grad():
            metrics["bc_action_mse"] = action_error(rows).item()
            if targets is not None:
                metrics["bc_value_mse"] = value_error(rows).item()
    return metrics


def mean_actions(agent: PPOAgent, obs_n: torch.Tensor, rows: DemoRows) -> torch.Tensor:
    """The policy's mean action at every step of `rows` (`[T, B, action]`), in env units: as it
    is for `clip` (demo actions lie inside the box, so the unclipped mean is pulled inside too),
    through `tanh` for `squash`. Each row runs from a fresh recurrent state."""
    policy = agent.policy
    dist, _ = policy.distribution(obs_n[rows.index], policy.initial_state(rows.width), rows.starts)
    return policy.actions.to_env(dist.mean) if isinstance(policy.actions, SquashGaussian) else dist.mean


def _rows(agent: PPOAgent, n: int, episode_starts: np.ndarray | None) -> DemoRows:
    if agent.policy.recurrent and episode_starts is None:
        raise ValueError("a recurrent policy is cloned on whole episodes: pass the demos' episode_starts")
    return demo_rows(np.ones(n, dtype=bool) if episode_starts is None else episode_starts, agent.policy.recurrent)


def fit_exploration_std(
    agent: PPOAgent, observations: np.ndarray, actions: np.ndarray, scale: float, low: float, high: float,
    episode_starts: np.ndarray | None = None,
) -> np.ndarray:
    """Size PPO's exploration noise from the pretrained policy instead of the preset's
    `init_log_std`: per action dimension, `scale` times the root-mean-square error of the policy's
    mean on the expert's actions, clipped to `[low, high]`; sets `actor_logstd` and returns the std.

    Why: with the preset's std of 1 in a [-1, 1] box the first rollouts after pretraining are
    mostly noise, the pretrained behaviour never shows in them, and PPO walks away from it
    (measured: held-out success 0.25 -> 0.05 within 20k steps). The cloning error is how far the
    student already is from its teacher, so noise of that size explores around the demonstrated
    behaviour without drowning it."""
    policy = agent.policy
    obs_n = agent.obs_normalizer(np.asarray(observations, dtype=np.float32), update=False)
    rows = _rows(agent, len(obs_n), episode_starts)
    with torch.no_grad():
        # the action the env would get: clipped or squashed
        predicted = policy.actions.to_env(policy.distribution(obs_n[rows.index], policy.initial_state(rows.width), rows.starts)[0].mean)
        error = predicted - torch.as_tensor(np.asarray(actions, dtype=np.float32))[rows.index]
        rmse = (error[rows.mask] ** 2).mean(dim=0).sqrt()
        std = (scale * rmse).clamp(low, high)
        policy.actor_logstd.copy_(std.log())
    return std.numpy()


def _critic_input(agent: PPOAgent, obs_n: torch.Tensor, privileged: np.ndarray | None) -> torch.Tensor | None:
    """The critic's input for the demos, or None when it cannot be built (module doc)."""
    width = agent.privileged_dim
    if width == 0:
        return obs_n
    if privileged is None or privileged.shape[1] > width:
        return None
    padded = np.zeros((len(privileged), width), dtype=np.float32)
    padded[:, : privileged.shape[1]] = privileged
    return torch.cat([obs_n, agent.privileged_normalizer(padded, update=True)], dim=-1)
