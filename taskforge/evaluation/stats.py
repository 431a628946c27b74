"""Confidence intervals for success rates."""

from __future__ import annotations

import math


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % Wilson score interval (Wilson, 1927) for a binomial proportion.

    Why Wilson and not p ± z·sqrt(p(1-p)/n): with 20 episodes and 0 or 20 successes the normal
    interval collapses to a point; Wilson stays honest at the extremes.
    """
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # clamped to contain p: at p = 0 or 1 rounding would otherwise leave it a hair outside
    return (min(p, max(0.0, centre - half)), max(p, min(1.0, centre + half)))
