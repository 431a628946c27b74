"""Planners of `algo: mpc`: search action sequences of `horizon` steps for the highest return the
model predicts, for a batch of envs at once. The agent executes the first action of the result
and plans again at the next step (receding horizon).

Actions are planned in [-1, 1] (the agent maps them onto the env's box). Each planner gets
`score(actions [envs, candidates, horizon, action]) -> returns [envs, candidates]` and the
previous step's plan shifted by one step (`warm`), and returns the new plan `[envs, horizon,
action]`. `proposals` (`[envs, k, horizon, action]`, or None) are sequences from elsewhere (the
demos' policy, `prior.py`) that join every round's candidates: a round's best can be one of
them, and CEM's elites and MPPI's weighted mean take them in like any other candidate.

* `random_shooting`: the best of `population` uniform sequences: what GenReL-World describes;
  no use of the previous plan.
* `cem` (PETS): `iterations` rounds of sampling around a Gaussian, then refitting its mean and
  std to the `elites` best; the refit is smoothed with the previous round's (`momentum`, PETS's
  alpha = 0.1), and the first round starts from the shifted previous plan.
* `mppi` (Williams et al. 2017): each round moves the mean to the candidates' average weighted
  by `exp(return / lambda)`; lambda is `temperature` times the round's return std, so one
  setting works whatever the reward's scale.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from taskforge.spec.agent import MPCSpec

Score = Callable[[torch.Tensor], torch.Tensor]


def plan(spec: MPCSpec, score: Score, warm: torch.Tensor, generator: torch.Generator,
         proposals: torch.Tensor | None = None) -> torch.Tensor:
    """The new plan `[envs, horizon, action]` (see the module doc)."""
    return PLANNERS[spec.planner](spec, score, warm, generator, proposals)


def random_shooting(spec: MPCSpec, score: Score, warm: torch.Tensor, generator: torch.Generator,
                    proposals: torch.Tensor | None = None) -> torch.Tensor:
    envs, horizon, actions = warm.shape
    candidates = _with(torch.rand((envs, spec.population, horizon, actions), generator=generator, device=warm.device) * 2 - 1, proposals)
    best = score(candidates).argmax(dim=1)
    return candidates[torch.arange(envs), best]


def cem(spec: MPCSpec, score: Score, warm: torch.Tensor, generator: torch.Generator,
        proposals: torch.Tensor | None = None) -> torch.Tensor:
    mean, std = warm, torch.full_like(warm, spec.init_std)
    for _ in range(spec.iterations):
        candidates = _with(_around(mean, std, spec.population, generator), proposals)
        top = score(candidates).topk(spec.elites, dim=1).indices
        elites = torch.gather(candidates, 1, top[:, :, None, None].expand(-1, -1, *candidates.shape[2:]))
        mean = spec.momentum * mean + (1 - spec.momentum) * elites.mean(dim=1)
        std = spec.momentum * std + (1 - spec.momentum) * elites.std(dim=1)
    return mean


def mppi(spec: MPCSpec, score: Score, warm: torch.Tensor, generator: torch.Generator,
         proposals: torch.Tensor | None = None) -> torch.Tensor:
    mean, std = warm, torch.full_like(warm, spec.init_std)
    for _ in range(spec.iterations):
        candidates = _with(_around(mean, std, spec.population, generator), proposals)
        returns = score(candidates)
        scale = spec.temperature * returns.std(dim=1, keepdim=True).clamp_min(1e-6)
        weights = torch.softmax((returns - returns.max(dim=1, keepdim=True).values) / scale, dim=1)
        mean = (weights[:, :, None, None] * candidates).sum(dim=1)
    return mean


def _around(mean: torch.Tensor, std: torch.Tensor, population: int, generator: torch.Generator) -> torch.Tensor:
    """`population` sequences per env drawn from N(mean, std), clipped to the action box."""
    noise = torch.randn((mean.shape[0], population, *mean.shape[1:]), generator=generator, device=mean.device)
    return (mean[:, None] + std[:, None] * noise).clamp(-1.0, 1.0)


def _with(candidates: torch.Tensor, proposals: torch.Tensor | None) -> torch.Tensor:
    """The drawn candidates and the proposals, side by side along the candidates' axis."""
    return candidates if proposals is None else torch.cat([candidates, proposals], dim=1)


def shift(plan: torch.Tensor) -> torch.Tensor:
    """The plan for the next step: drop the executed first action, repeat nothing (zeros last)."""
    return torch.cat([plan[:, 1:], torch.zeros_like(plan[:, :1])], dim=1)


PLANNERS: dict[str, Callable[[MPCSpec, Score, torch.Tensor, torch.Generator, torch.Tensor | None], torch.Tensor]] = {
    "random_shooting": random_shooting,
    "cem": cem,
    "mppi": mppi,
}
