"""The demonstrations' policy as a proposal for the planner of `algo: mpc` (`mpc.prior_trajectories`).

Why: a model fitted on scripted episodes alone is wrong off them, and the search finds where.
Measured on Meta-World pick-place: the 3 x 256 model fitted on 50 scripted episodes paid for
lifting the hand whether or not it held the object (in the demos it always did), so the planner
rose to the ceiling: 0 of 50 held-out goals right after the warm start, while the same episodes
cloned act at 8 of 8 (benchmarks/RESULTS.md). MoDem (Hansen et al. 2022), TD-MPC with
demonstrations, uses a policy cloned from the demos whose rollouts through the model join the
planner's candidates (TD-MPC's "policy-guided trajectories"); here the search also starts from
the noise-free rollout (mpc.py's doc: proposals alone did not help). Choices:

* **A deterministic MLP, mean squared error to the demo action** in [-1, 1], through `tanh`:
  the scripted actions are nearly deterministic (agents/bc.py makes the same choice for PPO).
* **Fitted once, on the demos only** (`warm_start.bc_epochs`, `bc_batch_size`,
  `bc_learning_rate`), then frozen. A departure from MoDem, which trains its policy on through
  TD-MPC's value: here the planner is the policy that improves, through the model it refits on
  every step it takes, and the prior stays what the demos showed.
* **Standardised inputs**, statistics of the demo observations (the planner's own states start
  from the same distribution).

The rollouts themselves (the policy stepped through the model's mean) are the agent's
(`MPCAgent._proposals`): they need its action scaling and model.
"""

from __future__ import annotations

import torch
from torch import nn

from taskforge.agents.dynamics import ensemble_mlp, run_mlp


class PolicyPrior(nn.Module):
    """pi(obs) -> action in [-1, 1], cloned from demonstrations."""

    def __init__(self, obs_size: int, action_size: int, hidden_sizes: list[int], generator: torch.Generator):
        super().__init__()
        self.net = ensemble_mlp(1, [obs_size, *hidden_sizes], action_size, generator)
        self.register_buffer("obs_mean", torch.zeros(obs_size))
        self.register_buffer("obs_std", torch.ones(obs_size))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Actions in [-1, 1] for observations `[n, obs]` -> `[n, action]`."""
        x = ((obs - self.obs_mean) / self.obs_std)[None]
        return torch.tanh(run_mlp(self.net, x)[0])

    def fit(self, obs: torch.Tensor, actions: torch.Tensor, epochs: int, batch_size: int, learning_rate: float,
            generator: torch.Generator) -> dict[str, float]:
        """Behaviour cloning on `(obs, actions in [-1, 1])` for `epochs` passes in shuffled
        minibatches; the last epoch's mean squared error, as a metric."""
        self.obs_mean.copy_(obs.mean(dim=0))
        self.obs_std.copy_(obs.std(dim=0).clamp_min(1e-6))  # a floor: constant inputs (a hidden goal's zeros)
        optimizer = torch.optim.Adam(self.net.parameters(), lr=learning_rate)
        last = float("nan")
        for _ in range(epochs):
            order, total = torch.randperm(len(obs), generator=generator).to(obs.device), 0.0
            for start in range(0, len(obs), batch_size):
                idx = order[start : start + batch_size]
                loss = ((self(obs[idx]) - actions[idx]) ** 2).mean()
                optimizer.zero_grad()
                loss.backward()
                optimizer.step()
                total += loss.item() * len(idx)
            last = total / len(obs)
        return {"prior_bc_mse": last}
