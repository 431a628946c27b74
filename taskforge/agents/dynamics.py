"""The learned model of `algo: mpc`: PETS's probabilistic ensemble (Chua et al. 2018).

Each of `ensemble_size` members is an MLP from (observation, action) to a diagonal Gaussian over
(next observation - observation, reward). Design choices, each PETS's or its reference
implementation's (mbrl-lib) unless said otherwise:

* **Probabilistic outputs** capture the env's own noise (aleatoric); **an ensemble** of members
  trained on different bootstrap draws of the data captures what the data does not pin down
  (epistemic). The planner then rolls each particle through one member for the whole horizon
  (TS-inf), so a plan that only looks good to one member scores worse on average.
* **Predict the change of the observation**, not the next one: most of an observation stays put
  in one step, and a network near zero output fits that at once.
* **Standardised inputs and targets**, statistics fitted on the whole buffer before each fit:
  positions (metres) and rewards (tens) then train at one step size. The reward's on the rows it
  learns from: in a curriculum, the stage being trained's (`MPCAgent`).
* **The reward has a network of its own, fitted by squared error** (a departure: PETS was given
  the reward function; taskforge's stage reward reads features the observation need not contain,
  so it is learnt). Sharing the trunk with the observation's likelihood failed: where the motion
  is nearly deterministic its log-variance sinks to the floor, its precision (e^10) scales that
  loss's gradients by thousands, and the shared layers serve it alone. Measured on the point
  mass after 2,400 steps: with the reward as one more likelihood output, and as a squared error
  on the shared trunk, the predicted reward at the goal was ~0.1 and ~0.0 where the data says
  0.96, and the planner wandered. The planner reads the reward's prediction, no noise.
* **β-NLL** (`nll_beta`; Seitzer et al. 2022, "On the pitfalls of heteroscedastic uncertainty
  estimation"; a departure from PETS, which uses β = 0, the plain likelihood): each dimension's
  negative log-likelihood is weighted by its predicted variance to the power β, held constant in
  the gradient. Why: the plain likelihood scales the gradient on a dimension's mean by one over
  its predicted variance, so a dimension the model calls noisy is learnt slowly, and stays
  noisy. On Meta-World, whose observation has constant columns (the absent second object) and
  copies (the previous frame), those sink to the log-variance floor and take the shared layers,
  and the hand and puck are left "noise": measured on pick-place's own 675k transitions, a
  refit with β = 0 predicted the puck's motion no better than "no motion" (2.9 mm off where it
  moved 2-5 mm; a linear map: 0.8), with β = 0.5 0.8 mm after the same 10k steps, and the same
  planner then placed 0.70 of 20 held-out goals instead of 0 (benchmarks/RESULTS.md). β = 1
  gives the mean the squared error's gradient.
* **Soft bounds on the log-variance** (learned `max_logvar` / `min_logvar`, pushed together by a
  small penalty): without them the Gaussian likelihood can drive a variance to zero on points it
  fits exactly, and the loss to minus infinity.
* **Batched members**: one `baddbmm` per layer runs all members at once (weights
  `[members, in, out]`), the cost that dominates planning on a CPU.
* SiLU activations, as mbrl-lib's default ("swish").
"""

from __future__ import annotations

import math

import torch
from torch import nn
from torch.nn import functional as F

from taskforge.spec.agent import MPCSpec


class EnsembleLinear(nn.Module):
    """`members` independent linear layers applied to `[members, n, in]` at once."""

    def __init__(self, members: int, inputs: int, outputs: int, generator: torch.Generator):
        super().__init__()
        # mbrl-lib's init: truncated normal, std 1 / (2 sqrt(fan_in)), zero bias
        std = 1.0 / (2.0 * math.sqrt(inputs))
        weight = torch.empty(members, inputs, outputs)
        nn.init.trunc_normal_(weight, std=std, a=-2 * std, b=2 * std, generator=generator)
        self.weight = nn.Parameter(weight)
        self.bias = nn.Parameter(torch.zeros(members, 1, outputs))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.baddbmm(self.bias, x, self.weight)


def ensemble_mlp(members: int, sizes: list[int], outputs: int, generator: torch.Generator) -> nn.ModuleList:
    """`members` MLPs of layer sizes `sizes` then `outputs`, as one stack of `EnsembleLinear`s."""
    return nn.ModuleList(
        [EnsembleLinear(members, a, b, generator) for a, b in zip(sizes[:-1], sizes[1:])]
        + [EnsembleLinear(members, sizes[-1], outputs, generator)]
    )


def run_mlp(layers: nn.ModuleList, x: torch.Tensor) -> torch.Tensor:
    """`ensemble_mlp`'s layers on `[members, n, in]`, SiLU between them."""
    for layer in layers[:-1]:
        x = F.silu(layer(x))
    return layers[-1](x)


class DynamicsEnsemble(nn.Module):
    """Per member, from `(obs, action)`: a Gaussian (mean, log-variance) over `next_obs - obs`,
    and the reward (a network of its own, module doc)."""

    def __init__(self, obs_size: int, action_size: int, spec: MPCSpec, generator: torch.Generator):
        super().__init__()
        self.members, self.obs_size, self.nll_beta = spec.ensemble_size, obs_size, spec.nll_beta
        sizes = [obs_size + action_size, *spec.hidden_sizes]
        self.dynamics = ensemble_mlp(self.members, sizes, 2 * obs_size, generator)
        self.reward = ensemble_mlp(self.members, sizes, 1, generator)
        self.max_logvar = nn.Parameter(torch.full((1, 1, obs_size), 0.5))
        self.min_logvar = nn.Parameter(torch.full((1, 1, obs_size), -10.0))
        for name, size in (("in", obs_size + action_size), ("out", obs_size + 1)):
            self.register_buffer(f"{name}_mean", torch.zeros(size))
            self.register_buffer(f"{name}_std", torch.ones(size))

    def fit_normalization(self, inputs: torch.Tensor, targets: torch.Tensor, rewards: torch.Tensor | None = None) -> None:
        """Standardise with the statistics of all the data (a floor on the std keeps a constant
        input, such as a hidden goal's zeros, from dividing by zero); the reward's with those of
        `rewards` where the reward learns from only some of the rows (`loss`)."""
        for name, data in (("in", inputs), ("out", targets)):
            getattr(self, f"{name}_mean").copy_(data.mean(dim=0))
            getattr(self, f"{name}_std").copy_(data.std(dim=0).clamp_min(1e-6))
        if rewards is not None and len(rewards) > 1:
            self.out_mean[-1], self.out_std[-1] = rewards.mean(), rewards.std().clamp_min(1e-6)

    def forward(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Standardised `[members, n, obs + action]` -> the standardised observation change's
        mean and log-variance (`[members, n, obs]` each) and the standardised reward `[members, n]`."""
        mean, logvar = self._change(inputs)
        return mean, logvar, run_mlp(self.reward, inputs)[..., 0]

    def _change(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mean, logvar = run_mlp(self.dynamics, inputs).chunk(2, dim=-1)
        logvar = self.max_logvar - F.softplus(self.max_logvar - logvar)  # soft bounds (module doc)
        logvar = self.min_logvar + F.softplus(logvar - self.min_logvar)
        return mean, logvar

    def loss(self, inputs: torch.Tensor, targets: torch.Tensor,
             reward_batch: tuple[torch.Tensor, torch.Tensor] | None = None) -> torch.Tensor:
        """For raw `targets` (`[members, n, obs + 1]`: observation change, reward): the Gaussian
        negative log-likelihood of the change (each dimension's weighted by its variance to the
        power `nll_beta`, module doc), summed over dimensions, plus the reward's squared
        error, each averaged over members and samples; plus PETS's 0.01 penalty on the
        log-variance bounds. `reward_batch` (raw inputs `[members, m, obs + action]`, rewards
        `[members, m]`): the reward's own rows, where it learns from other rows than the motion
        (the stage being trained's, `MPCAgent`); otherwise `targets`' last column."""
        x = (inputs - self.in_mean) / self.in_std
        mean, logvar = self._change(x)
        target = (targets[..., :-1] - self.out_mean[:-1]) / self.out_std[:-1]
        nll = ((mean - target) ** 2) * torch.exp(-logvar) + logvar
        if self.nll_beta:  # β-NLL: the weight is a constant in the gradient (detached)
            nll = nll * torch.exp(self.nll_beta * logvar.detach())
        nll = nll.sum(dim=-1).mean()
        reward_x, rewards = (x, targets[..., -1]) if reward_batch is None else ((reward_batch[0] - self.in_mean) / self.in_std, reward_batch[1])
        reward = run_mlp(self.reward, reward_x)[..., 0]
        reward_error = ((reward - (rewards - self.out_mean[-1]) / self.out_std[-1]) ** 2).mean()
        return nll + reward_error + 0.01 * (self.max_logvar.sum() - self.min_logvar.sum())

    def fit_batch(self, optimizer: torch.optim.Optimizer, inputs: torch.Tensor, targets: torch.Tensor,
                  reward_batch: tuple[torch.Tensor, torch.Tensor] | None = None) -> float:
        """One Adam step on `loss` for `[members, batch, ...]` raw inputs and targets; the loss."""
        loss = self.loss(inputs, targets, reward_batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        return loss.item()

    def _predict(self, obs: torch.Tensor, actions: torch.Tensor, generator: torch.Generator | None) -> tuple[torch.Tensor, torch.Tensor]:
        mean, logvar, reward = self((torch.cat([obs, actions], dim=-1) - self.in_mean) / self.in_std)
        change = mean if generator is None else mean + torch.exp(0.5 * logvar) * torch.randn(mean.shape, generator=generator, device=mean.device)
        change = change * self.out_std[:-1] + self.out_mean[:-1]
        return obs + change, reward * self.out_std[-1] + self.out_mean[-1]

    def sample(self, obs: torch.Tensor, actions: torch.Tensor, generator: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """One draw of the next observation, and the predicted reward, for `[members, n, ...]`
        inputs, member b predicting row block b (what the planner's particles read)."""
        return self._predict(obs, actions, generator)

    def mean_prediction(self, obs: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The members' mean next observation and reward (`[members, n, ...]`): for measuring the
        model's error, not for planning."""
        return self._predict(obs, actions, None)
