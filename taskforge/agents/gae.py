"""Generalised advantage estimation (core detail #5) that tells time limits from terminations.

CleanRL folds truncation into `done` and so treats a time limit as a terminal state worth zero,
which biases values near the limit (Pardo et al., 2018, "Time Limits in Reinforcement
Learning"). Here the two flags play different roles:

* `terminated[t]`: the MDP ended; nothing follows, the bootstrap term is zero.
* `terminated[t] or truncated[t]`: the episode ended; the lambda-trace is cut, because the next
  stored step belongs to a new episode.

So on truncation the TD error still bootstraps from `next_values[t]`, which the caller sets to
the value of the final observation (`infos["final_obs"]` under SAME_STEP autoreset).
"""

from __future__ import annotations

import torch


def compute_gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    next_values: torch.Tensor,
    terminated: torch.Tensor,
    truncated: torch.Tensor,
    gamma: float,
    lam: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Advantages and returns (`advantages + values`, the value targets) for `[T, N]` arrays.

    Args:
        rewards: reward received after the action at step t.
        values: V(s_t) as estimated during the rollout.
        next_values: V of the observation that followed step t *in the same episode*: V(s_{t+1})
            normally, V(final observation) where the episode was truncated at t (ignored where
            it terminated).
        terminated, truncated: boolean end-of-episode flags of step t.
        gamma, lam: discount and GAE's lambda.
    """
    not_terminal = 1.0 - terminated.to(rewards.dtype)
    not_done = 1.0 - (terminated | truncated).to(rewards.dtype)
    advantages = torch.zeros_like(rewards)
    last_gae = torch.zeros_like(rewards[0])
    for t in reversed(range(rewards.shape[0])):
        delta = rewards[t] + gamma * next_values[t] * not_terminal[t] - values[t]
        last_gae = delta + gamma * lam * not_done[t] * last_gae
        advantages[t] = last_gae
    return advantages, advantages + values
