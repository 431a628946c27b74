"""Distance kernels: map a distance d >= 0 to a reward in [0, 1], 1 at d = 0.

They follow dm_control's `rewards.tolerance` (which Meta-World's v2 rewards also use): the
`margin` is where the reward has fallen to `value_at_margin`, so the same two numbers mean the
same thing whatever the kernel's shape. `negative` is the raw `-d` (no margin) for dense
distance penalties.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal

Kernel = Callable[[float, float, float], float]


def _gaussian(d: float, margin: float, value_at_margin: float) -> float:
    scale = math.sqrt(-2.0 * math.log(value_at_margin))
    return math.exp(-0.5 * (d * scale / margin) ** 2)


def _long_tail(d: float, margin: float, value_at_margin: float) -> float:
    """Never reaches zero: a signal even far from the target."""
    scale = math.sqrt(1.0 / value_at_margin - 1.0)
    return 1.0 / ((d * scale / margin) ** 2 + 1.0)


def _linear(d: float, margin: float, value_at_margin: float) -> float:
    scale = 1.0 - value_at_margin
    return max(0.0, 1.0 - d * scale / margin)


def _exponential(d: float, margin: float, value_at_margin: float) -> float:
    return math.exp(math.log(value_at_margin) * d / margin)


def _negative(d: float, margin: float, value_at_margin: float) -> float:
    return -d


KERNELS: dict[str, Kernel] = {
    "gaussian": _gaussian,
    "long_tail": _long_tail,
    "linear": _linear,
    "exponential": _exponential,
    "negative": _negative,
}

KernelName = Literal[tuple(KERNELS)]  # type: ignore[valid-type]
"""The names a `kernel:` parameter accepts, read from `KERNELS` so a new kernel is one entry."""
