"""Drawing from the `Distribution` of a spec with a caller-supplied generator (never global
state), so the same seed gives the same draws."""

from __future__ import annotations

import numpy as np

from taskforge.spec import Distribution


def sample(dist: Distribution, rng: np.random.Generator, size: int | tuple[int, ...] = ()) -> np.ndarray:
    if dist.dist == "uniform":
        return rng.uniform(dist.low, dist.high, size)
    if dist.dist == "loguniform":
        return np.exp(rng.uniform(np.log(dist.low), np.log(dist.high), size))
    return rng.normal(dist.mean or 0.0, dist.std, size)
