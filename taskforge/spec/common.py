"""Building blocks shared by the task, agent and curriculum schemas."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class StrictModel(BaseModel):
    """Base of every schema model: unknown keys are errors, values are not coerced silently."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)


class Distribution(StrictModel):
    """A scalar distribution, as in the physics-randomisation table of *Learning Dexterity*.

    `uniform` and `loguniform` use `low`/`high`; `normal` uses `mean` (default 0) and `std`. Loguniform draws
    `exp(U(log low, log high))`, which is what a ×[0.3, 3] damping range wants: as likely to halve
    as to double.
    """

    dist: Literal["uniform", "loguniform", "normal"]
    low: float | None = None
    high: float | None = None
    mean: float | None = None
    std: float | None = Field(default=None, ge=0.0)

    @model_validator(mode="after")
    def _check_parameters(self) -> Distribution:
        if self.dist in ("uniform", "loguniform"):
            if self.low is None or self.high is None:
                raise ValueError(f"a {self.dist} distribution needs 'low' and 'high'")
            if not (math.isfinite(self.low) and math.isfinite(self.high)):
                raise ValueError("'low' and 'high' must be finite numbers")
            if self.low > self.high:
                raise ValueError(f"'low' ({self.low}) must be <= 'high' ({self.high})")
            if self.dist == "loguniform" and self.low <= 0:
                raise ValueError(f"a loguniform distribution needs 'low' > 0 (got {self.low})")
            if self.std is not None or self.mean is not None:
                raise ValueError(f"'mean'/'std' belong to a normal distribution, not {self.dist}")
        else:
            if self.std is None:
                raise ValueError("a normal distribution needs 'std' (>= 0)")
            if self.low is not None or self.high is not None:
                raise ValueError("'low'/'high' belong to uniform/loguniform, not normal")
        return self

    def describe(self) -> str:
        if self.dist == "normal":
            return f"N({self.mean or 0.0:g}, {self.std:g})"
        return f"{self.dist}[{self.low:g}, {self.high:g}]"
