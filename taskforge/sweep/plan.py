"""A sweep file turned into trials: each variant written out as files of its own (a curriculum,
agent and tasks whose `base:` is the original, plus the variant's overrides), checked exactly as
`taskforge validate` checks any curriculum, with each mistake reported at the sweep file's field.

Why files and `base:` rather than dicts merged in memory: a trial is then an ordinary run of
`taskforge train` on files a user can open, validate and re-run by hand, and the one merge rule
of the project (docs/authoring.md, "Variants of a file") is the only one.
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from taskforge.envs import load_curriculum, load_task
from taskforge.spec import (
    SpecError,
    SpecIssue,
    SweepSpec,
    TaskSpec,
    expected_one_of,
    load_sweep_spec,
    read_curriculum_yaml,
    resolve_relative,
)

CURRICULUM, AGENT = "curriculum.yaml", "agent.yaml"


def slug(name: str) -> str:
    """A variant's folder name: lower case, runs of anything but letters and digits as one dash."""
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-") or "variant"


@dataclass(frozen=True)
class Trial:
    """One (variant, seed): an ordinary `taskforge train` run."""

    variant: str
    seed: int
    curriculum_file: Path
    run_dir: Path


@dataclass(frozen=True)
class Condition:
    """A test condition: the task every trained policy is evaluated on."""

    name: str
    task: TaskSpec
    task_file: Path


@dataclass(frozen=True)
class SweepPlan:
    file: Path
    spec: SweepSpec
    out: Path
    trials: list[Trial]
    conditions: list[Condition]
    stage: str
    """The stage the conditions are evaluated on."""

    def variant_names(self) -> list[str]:
        return [v.name for v in self.spec.variants]


def _variant_files(spec: SweepSpec, sweep_file: Path, index: int) -> dict[str, dict[str, Any]]:
    """The files of variant `index`, by name: each a `base:` (absolute) plus the overrides."""
    variant = spec.variants[index]
    base_file = resolve_relative(sweep_file, spec.curriculum).resolve()
    merged = read_curriculum_yaml(base_file)
    files: dict[str, dict[str, Any]] = {}
    curriculum: dict[str, Any] = {"base": str(base_file), **variant.curriculum}
    # paths a variant writes are relative to the sweep file, those of the base to the base
    own = variant.curriculum
    agent_ref = own.get("agent", merged.get("agent"))
    agent_home = sweep_file if "agent" in own else base_file
    if variant.agent and isinstance(agent_ref, str):
        files[AGENT] = {"base": str(resolve_relative(agent_home, agent_ref).resolve()), **variant.agent}
        curriculum["agent"] = AGENT
    elif "agent" in own and isinstance(agent_ref, str):
        curriculum["agent"] = str(resolve_relative(sweep_file, agent_ref).resolve())
    phases = own.get("phases", merged.get("phases"))
    phases_home = sweep_file if "phases" in own else base_file
    if isinstance(phases, list) and (variant.task or "phases" in own):
        rewritten = []
        for k, phase in enumerate(phases):
            if not (isinstance(phase, dict) and isinstance(phase.get("task"), str)):
                rewritten.append(phase)
                continue
            task_path = str(resolve_relative(phases_home, phase["task"]).resolve())
            if variant.task:
                files[f"task_{k}.yaml"] = {"base": task_path, **variant.task}
                task_path = f"task_{k}.yaml"
            rewritten.append({**phase, "task": task_path})
        curriculum["phases"] = rewritten
    if spec.total_steps is not None:
        curriculum["total_steps"] = spec.total_steps
    files[CURRICULUM] = curriculum
    return files


def _write(folder: Path, files: dict[str, dict[str, Any]]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, doc in files.items():
        (folder / name).write_text(yaml.safe_dump(doc, sort_keys=False))


def _as_sweep_issues(issues: Iterable[SpecIssue], written: dict[Path, str], sweep_file: Path) -> list[SpecIssue]:
    """Issues found in generated files, moved to the sweep file's field that wrote them (`written`:
    generated file -> field prefix); issues of the original files stay where they are."""
    moved = []
    for issue in issues:
        prefix = written.get(Path(issue.file).resolve())
        if prefix is None:
            moved.append(issue)
        else:
            field = f"{prefix}.{issue.path}" if issue.path else prefix
            moved.append(SpecIssue(str(sweep_file), field, issue.message))
    return moved


def plan_sweep(sweep_file: str | Path, out: str | Path | None = None) -> SweepPlan:
    """Check a sweep file and everything it names; raises one `SpecError` with every mistake.
    Writes nothing (the checks run on files in a temporary folder)."""
    sweep_file = Path(sweep_file)
    spec = load_sweep_spec(sweep_file)
    base_file = resolve_relative(sweep_file, spec.curriculum)
    if not base_file.is_file():
        raise SpecError.single(sweep_file, "curriculum", f"file not found: {base_file}")
    base = load_curriculum(base_file)  # the base's own mistakes first, named in its own files
    issues: list[SpecIssue] = []
    folders = [slug(v.name) for v in spec.variants]
    for i, folder in enumerate(folders):
        if folders.index(folder) != i:
            msg = f"'{spec.variants[i].name}' and '{spec.variants[folders.index(folder)].name}' share the folder name '{folder}'; rename one"
            issues.append(SpecIssue(str(sweep_file), f"variants[{i}].name", msg))
    with tempfile.TemporaryDirectory(prefix="taskforge-sweep-") as tmp:
        for i in range(len(spec.variants)):
            folder = Path(tmp) / str(i)
            files = _variant_files(spec, sweep_file, i)
            _write(folder, files)
            written = {(folder / name).resolve(): f"variants[{i}].{_kind(name)}" for name in files}
            try:
                load_curriculum(folder / CURRICULUM)
            except SpecError as exc:
                issues += _as_sweep_issues(exc.issues, written, sweep_file)
        last_task_file = base.phases[-1].task_file.resolve()
        stage = spec.evaluation.stage or base.phases[-1].stages[-1]
        if stage not in base.phases[-1].task.stage_names:
            known = base.phases[-1].task.stage_names
            issues.append(SpecIssue(str(sweep_file), "evaluation.stage", f"no stage '{stage}' in {last_task_file}; {expected_one_of(stage, known)}"))
        conditions = []
        for k, condition in enumerate(spec.evaluation.conditions):
            path = Path(tmp) / f"condition_{k}.yaml"
            _write(Path(tmp), {path.name: {"base": str(last_task_file), **condition.task}})
            try:
                conditions.append(Condition(condition.name, load_task(path), path))
            except SpecError as exc:
                issues += _as_sweep_issues(exc.issues, {path.resolve(): f"evaluation.conditions[{k}].task"}, sweep_file)
    if issues:
        raise SpecError(issues)
    # absolute: Ray's workers may start in another directory
    out = (Path(out) if out is not None else Path("runs") / "sweeps" / spec.name).resolve()
    # seed by seed: an interrupted sweep has every variant of its first seeds, a whole table
    trials = [
        Trial(v.name, seed, out / slug(v.name) / CURRICULUM, out / slug(v.name) / f"seed{seed}")
        for seed in spec.seeds for v in spec.variants
    ]
    conditions = [Condition(c.name, c.task, out / "conditions" / f"{slug(c.name)}.yaml") for c in conditions]
    return SweepPlan(sweep_file, spec, out, trials, conditions, stage)


def _kind(file_name: str) -> str:
    return {CURRICULUM: "curriculum", AGENT: "agent"}.get(file_name, "task")


def write_plan(plan: SweepPlan) -> None:
    """Write each variant's files and each condition's task file under `plan.out` (what the
    trials run and the tables name)."""
    last_task_file = load_curriculum(resolve_relative(plan.file, plan.spec.curriculum)).phases[-1].task_file.resolve()
    for i, variant in enumerate(plan.spec.variants):
        _write(plan.out / slug(variant.name), _variant_files(plan.spec, plan.file, i))
    for condition, written in zip(plan.spec.evaluation.conditions, plan.conditions):
        _write(written.task_file.parent, {written.task_file.name: {"base": str(last_task_file), **condition.task}})
