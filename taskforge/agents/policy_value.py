"""TD-MPC's terminal value for `algo: mpc` (`mpc.value_policy`): `Q(s, pi(s))` of a policy `pi`
learnt from the buffer, scoring each plan's last state in place of `value.py`'s V, and `pi` itself
proposing rollouts to the planner (`mpc.prior_trajectories`).

Why: V is the value of the data's behaviour, and on push it misled the planner wherever it was
refitted. Measured with push seed 1's 120k model and search fixed, on 30 held-out goals (its first
100k transitions; benchmarks/mpc_probe.py, benchmarks/RESULTS.md): every V refit planned 0.10-0.30
(all inputs, relative inputs, no gripper, discounts 0.95 and 0.9, the first 50k rows); this Q,
fitted offline on the same rows, planned 0.60, and 0.87 with 5 of pi's rollouts among each round's
candidates (pi alone, no model and no search: 0.43). TD-MPC (Hansen et al. 2022) plans the same
way: the model's rewards over the horizon plus the value of the learnt policy after it, and that
policy's rollouts among the candidates. Design choices:

* **TD3+BC (Fujimoto & Gu 2021)** rather than TD-MPC's own latent TD learning: the data is the
  planner's, so `pi` must stay near the actions it took, where Q is fitted; TD3+BC's cloning term
  does that with one weight (`alpha`, `mpc.value_policy_alpha`, theirs 2.5) and its defaults are
  what the measured fit used: twin Q (the smaller one bootstraps), target-policy noise 0.2 clipped
  at 0.5, `pi` and the target networks updated every 2nd step, Polyak 0.005 (`mpc.value_tau`'s
  default), Adam at 3e-4.
* **Targets optionally within the rewards' range** (`mpc.value_bound`; value.py's `target_range`):
  TD3's min over two heads did not stop push seed 0's first fit from running Q to ~12x its
  rows' worth, both heads together; the clip to `[min r, max r] / (1 - discount)` does.
* **The planner reads the first Q head** at `pi`'s action, as TD3's actor does.
* **Inputs standardised by the model's statistics** (refitted before each fit), outputs in units
  of 1 / (1 - discount), as V's; time limits bootstrapped, termination not modelled (mpc.py).
* **`pi` is a `PolicyPrior`** (prior.py): the same network the demos' prior is, so a warm start
  clones the demos into it and the proposals read it the same way.
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from taskforge.agents.dynamics import ensemble_mlp, run_mlp
from taskforge.agents.prior import PolicyPrior
from taskforge.agents.value import polyak, target_range

LEARNING_RATE = 3e-4  # TD3's Adam step, for Q and pi alike
TARGET_NOISE, NOISE_CLIP = 0.2, 0.5  # target-policy smoothing (in [-1, 1] action units)
POLICY_DELAY = 2  # pi and the targets move every 2nd Q step


class PolicyValue(nn.Module):
    """`Q(s, pi(s))` as the planner's score of observations `[..., obs]` -> `[...]`, with `pi`
    (`policy`) to act and propose, twin Q heads and target copies of both."""

    def __init__(self, obs_size: int, action_size: int, hidden_sizes: list[int], discount: float, tau: float,
                 generator: torch.Generator, alpha: float = 2.5, bound: bool = False):
        super().__init__()
        self.discount, self.scale, self.tau, self.alpha = discount, 1.0 / (1.0 - discount), tau, alpha
        self.bound = bound
        self.q = ensemble_mlp(2, [obs_size + action_size, *hidden_sizes], 1, generator)
        self.policy = PolicyPrior(obs_size, action_size, hidden_sizes, generator)
        self.q_target = copy.deepcopy(self.q).requires_grad_(False)
        self.policy_target = copy.deepcopy(self.policy).requires_grad_(False)

    def optimizers(self) -> tuple[torch.optim.Optimizer, torch.optim.Optimizer]:
        """Fresh Adam for Q and for pi (TD3's step size)."""
        return torch.optim.Adam(self.q.parameters(), lr=LEARNING_RATE), torch.optim.Adam(self.policy.parameters(), lr=LEARNING_RATE)

    def both(self, obs: torch.Tensor, actions: torch.Tensor, target: bool = False) -> torch.Tensor:
        """Both Q heads of `[n, obs]`, `[n, action]` -> `[2, n]` (of the target heads if `target`)."""
        x = torch.cat([(obs - self.policy.obs_mean) / self.policy.obs_std, actions], dim=-1)
        return run_mlp(self.q_target if target else self.q, x[None].expand(2, -1, -1)).squeeze(-1) * self.scale

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        flat = obs.reshape(-1, obs.shape[-1])
        return self.both(flat, self.policy(flat))[0].reshape(obs.shape[:-1])

    def fit(self, obs: torch.Tensor, actions: torch.Tensor, rewards: torch.Tensor, next_obs: torch.Tensor, mean: torch.Tensor,
            std: torch.Tensor, optimizers: tuple[torch.optim.Optimizer, torch.optim.Optimizer], updates: int, batch: int,
            generator: torch.Generator) -> dict[str, float]:
        """`updates` TD3+BC steps on random batches of the transitions (`actions` in [-1, 1]);
        Q's mean loss (squared value units / scale²), the last policy loss and the mean Q of pi's
        actions, as metrics."""
        self.policy.obs_mean.copy_(mean)
        self.policy.obs_std.copy_(std)
        self.policy_target.obs_mean.copy_(mean)
        self.policy_target.obs_std.copy_(std)
        q_optimizer, policy_optimizer = optimizers
        total, metrics = 0.0, {}
        low, high = target_range(rewards, self.scale, self.bound)  # mpc.value_bound; without it (-inf, inf)
        for step in range(updates):
            idx = torch.randint(len(rewards), (batch,), generator=generator).to(obs.device)
            with torch.no_grad():  # TD3's target: the target policy's action, smoothed, at the smaller target Q
                noise = (torch.randn(batch, actions.shape[1], generator=generator).to(obs.device) * TARGET_NOISE).clamp(-NOISE_CLIP, NOISE_CLIP)
                next_action = (self.policy_target(next_obs[idx]) + noise).clamp(-1.0, 1.0)
                target = rewards[idx] + self.discount * self.both(next_obs[idx], next_action, target=True).min(dim=0).values
                target = target.clamp(low, high)
            q_loss = (((self.both(obs[idx], actions[idx]) - target) / self.scale) ** 2).mean()
            q_optimizer.zero_grad()
            q_loss.backward()
            q_optimizer.step()
            total += q_loss.item()
            if step % POLICY_DELAY:  # delayed policy update: Q scaled by its own size (TD3+BC's lambda) plus cloning
                chosen = self.policy(obs[idx])
                q = self.both(obs[idx], chosen)[0]
                policy_loss = -self.alpha * q.mean() / q.abs().mean().detach() + ((chosen - actions[idx]) ** 2).mean()
                policy_optimizer.zero_grad()
                policy_loss.backward()
                policy_optimizer.step()
                polyak(self.q_target.parameters(), self.q.parameters(), self.tau)
                polyak(self.policy_target.parameters(), self.policy.parameters(), self.tau)
                metrics = {"policy_loss": policy_loss.item(), "value_mean": q.mean().item()}
        return {"value_loss": total / max(updates, 1), **metrics}
