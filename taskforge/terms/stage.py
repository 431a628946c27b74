"""A stage's reward and success condition, compiled from its spec against the registries.

`check_task` reports every unknown term, bad parameter and unknown feature with its field path;
`CompiledStage` is what the env calls on every step, so it avoids per-step allocation beyond the
small dict of term values that goes into `info`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pydantic import ValidationError

from taskforge.spec import SpecError, SpecIssue, StageSpec, StrictModel, TaskSpec, expected_one_of
from taskforge.spec.errors import issues_from_validation
from taskforge.spec.loader import field_names_at
from taskforge.terms.features import FEATURES, SCALAR_FEATURES, Features, env_features
from taskforge.terms.rewards import REWARD_TERMS, TermFn


@dataclass(frozen=True)
class BoundTerm:
    key: str
    """Name under which the term's value appears in `info["reward_terms"]`."""
    weight: float
    fn: TermFn
    params: StrictModel


class CompiledStage:
    """Reward = sum of weight * term(features); success = all conditions hold."""

    def __init__(self, spec: StageSpec, file: str | Path = "<task>", path: str = "stage"):
        issues = stage_issues(spec, file, path)
        if issues:
            raise SpecError(issues)
        self.spec = spec
        self.name = spec.name
        self.terms = _bind_terms(spec)
        self.reads = frozenset(f for t in spec.rewards for f in REWARD_TERMS[t.term].reads) | {c.feature for c in spec.success.all}
        """Every feature the stage's terms and success condition read."""
        # (feature, below, above) with +-inf standing in for a missing bound.
        self._conditions = [
            (c.feature, float("inf") if c.below is None else c.below,
             float("-inf") if c.above is None else c.above)
            for c in spec.success.all
        ]
        self.hold_steps = spec.success.hold_steps
        """Steps in a row `success` must hold before the stage succeeds (the env counts them)."""

    def success(self, features: Features) -> bool:
        for name, below, above in self._conditions:
            value = features[name]
            if not (above < value < below):
                return False
        return True

    def reward(self, features: Features) -> tuple[float, dict[str, float]]:
        """The total reward and each term's (unweighted) value."""
        values = {}
        total = 0.0
        for term in self.terms:
            value = term.fn(features, term.params)
            values[term.key] = value
            total += term.weight * value
        return total, values


def _bind_terms(spec: StageSpec) -> list[BoundTerm]:
    bound = []
    for term_spec in spec.rewards:
        term = REWARD_TERMS[term_spec.term]
        key = term_spec.term
        n = 1
        while any(b.key == key for b in bound):
            n += 1
            key = f"{term_spec.term}#{n}"
        bound.append(BoundTerm(key, term_spec.weight, term.fn, term.params.model_validate(term_spec.params)))
    return bound


def stage_issues(spec: StageSpec, file: str | Path, path: str) -> list[SpecIssue]:
    """Everything about a stage that the schema alone cannot check."""
    issues: list[SpecIssue] = []
    for j, term_spec in enumerate(spec.rewards):
        where = f"{path}.rewards[{j}]"
        term = REWARD_TERMS.get(term_spec.term)
        if term is None:
            msg = f"unknown reward term '{term_spec.term}'; {expected_one_of(term_spec.term, REWARD_TERMS)}"
            issues.append(SpecIssue(str(file), f"{where}.term", msg))
            continue
        try:
            term.params.model_validate(term_spec.params)
        except ValidationError as exc:
            prefix = [*_split_path(where), "params"]
            issues += issues_from_validation(
                exc, file, prefix, allowed_keys=lambda loc, m=term.params: field_names_at(m, loc)
            )
    for j, cond in enumerate(spec.success.all):
        where = f"{path}.success.all[{j}].feature"
        if cond.feature not in FEATURES:
            msg = f"unknown feature '{cond.feature}'; {expected_one_of(cond.feature, SCALAR_FEATURES)}"
            issues.append(SpecIssue(str(file), where, msg))
        elif cond.feature == "stage_success":
            issues.append(SpecIssue(str(file), where, "'stage_success' is this condition's own result; use another feature"))
        elif cond.feature not in SCALAR_FEATURES:
            msg = f"'{cond.feature}' is a vector; a condition needs a scalar feature: {', '.join(sorted(SCALAR_FEATURES))}"
            issues.append(SpecIssue(str(file), where, msg))
    return issues


def task_issues(task: TaskSpec, file: str | Path, provides: frozenset[str] | None = None) -> list[SpecIssue]:
    """Registry checks for every stage; with `provides` (the backend's features), also that each
    term and condition reads only features the backend fills."""
    issues: list[SpecIssue] = []
    for i, stage in enumerate(task.stages):
        issues += stage_issues(stage, file, f"stages[{i}]")
    if provides is None or issues:
        return issues
    available = provides | env_features(provides)
    for i, stage in enumerate(task.stages):
        for j, term_spec in enumerate(stage.rewards):
            missing = [f for f in REWARD_TERMS[term_spec.term].reads if f not in available]
            if missing:
                msg = f"term '{term_spec.term}' reads {', '.join(missing)}, which the {task.backend.type} backend does not provide"
                issues.append(SpecIssue(str(file), f"stages[{i}].rewards[{j}].term", msg))
        for j, cond in enumerate(stage.success.all):
            if cond.feature not in available:
                msg = f"the {task.backend.type} backend does not provide '{cond.feature}'; it provides {', '.join(sorted(available & SCALAR_FEATURES))}"
                issues.append(SpecIssue(str(file), f"stages[{i}].success.all[{j}].feature", msg))
    return issues


def _split_path(path: str) -> list[str | int]:
    """`stages[2].rewards[0]` -> ['stages', 2, 'rewards', 0] (for error prefixes)."""
    parts: list[str | int] = []
    for chunk in path.split("."):
        name, *indices = chunk.split("[")
        if name:
            parts.append(name)
        parts += [int(ix.rstrip("]")) for ix in indices]
    return parts
