"""Loading files with *every* check: the schema, then the registries (reward terms, features,
backend environment names), then the files a curriculum refers to. All mistakes come back
together as one `SpecError`, one line each."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from taskforge.backends import backend_features, backend_issues
from taskforge.spec import (
    SEED_PLACEHOLDER,
    AgentSpec,
    CurriculumSpec,
    SpecError,
    SpecIssue,
    TaskSpec,
    expected_one_of,
    init_for_seed,
    load_agent_spec,
    load_curriculum_spec,
    load_task_spec,
    resolve_relative,
)
from taskforge.terms import GOAL_FEATURES, task_issues


def load_task(path: str | Path) -> TaskSpec:
    task = load_task_spec(path)
    issues = backend_issues(task, path)
    if not issues:
        issues = task_issues(task, path, backend_features(task))
    if issues:
        raise SpecError(issues)
    return task


@dataclass(frozen=True)
class CurriculumPhase:
    task_file: Path
    task: TaskSpec
    stages: list[str]


@dataclass(frozen=True)
class ResolvedCurriculum:
    file: Path
    spec: CurriculumSpec
    agent_file: Path
    agent: AgentSpec
    phases: list[CurriculumPhase]
    demos_file: Path | None = None
    """`warm_start.demos`, resolved relative to the curriculum file."""
    init_from: Path | None = None
    """`init_from` (a run directory or checkpoint file), resolved relative to the curriculum file;
    may hold `{seed}` (`init_source` fills it)."""
    warnings: tuple[str, ...] = ()
    """Legal but probably unintended (see `curriculum_warnings`): `validate` and `train` print them
    and `train` writes them to the run's events."""

    def init_source(self, seed: int) -> Path | None:
        """The run directory or checkpoint the run of `seed` starts from (`init_from` with its
        `{seed}` filled); None without `init_from`."""
        return None if self.init_from is None else Path(init_for_seed(str(self.init_from), seed))

    def warm_start_phases(self) -> list[CurriculumPhase]:
        """The phases the warm start's demos and DAgger rollouts come from (`warm_start.phase`)."""
        ws = self.spec.warm_start
        if ws is None:
            return []
        return list(self.phases) if ws.phase == "all" else [self.phases[ws.phase]]


def load_curriculum(path: str | Path) -> ResolvedCurriculum:
    """A curriculum with its agent preset and task files loaded and cross-checked."""
    path = Path(path)
    spec = load_curriculum_spec(path)
    issues: list[SpecIssue] = []
    agent_file = resolve_relative(path, spec.agent)
    agent = _collect(issues, load_agent_spec, agent_file, path, "agent")
    phases = []
    for i, phase in enumerate(spec.phases):
        task_file = resolve_relative(path, phase.task)
        task = _collect(issues, load_task, task_file, path, f"phases[{i}].task")
        if task is None:
            continue
        for j, stage in enumerate(phase.stages):
            if stage not in task.stage_names:
                msg = f"no stage '{stage}' in {task_file}; {expected_one_of(stage, task.stage_names)}"
                issues.append(SpecIssue(str(path), f"phases[{i}].stages[{j}]", msg))
        phases.append(CurriculumPhase(task_file, task, list(phase.stages) or task.stage_names))
        eval_stage = spec.evaluation.stage
        if eval_stage is not None and eval_stage not in task.stage_names:
            msg = f"no stage '{eval_stage}' in {task_file} (phase {i + 1}); {expected_one_of(eval_stage, task.stage_names)}"
            issues.append(SpecIssue(str(path), "evaluation.stage", msg))
    demos_file = None
    if spec.warm_start is not None and not issues:
        demos_file = _check_warm_start(spec, path, agent, phases, issues)
    if agent is not None and agent.algo == "mpc" and agent.planning.prior_trajectories and not agent.planning.value_policy \
            and spec.warm_start is None:
        msg = (f"{agent.planning.prior_trajectories} proposals of a policy cloned from demonstrations, but {path} has no "
               "warm_start to clone it from; expected 0, a warm_start section in the curriculum, or mpc.value_policy: true (its "
               "learnt policy proposes)")
        issues.append(SpecIssue(str(agent_file), "mpc.prior_trajectories", msg))
    init_from = None
    if spec.init_from is not None:
        init_from = resolve_relative(path, spec.init_from)
        if spec.warm_start is not None:
            msg = "both set the policy a run starts from; expected one of init_from (a trained run) and warm_start (demonstrations)"
            issues.append(SpecIssue(str(path), "init_from", msg))
        elif SEED_PLACEHOLDER not in spec.init_from and not init_from.exists():
            # with `{seed}` the source depends on the seed, known when a run starts: `train` and
            # `validate` (at the curriculum's seed) check it then, in `load_init_from`
            issues.append(SpecIssue(str(path), "init_from", f"no such run directory or checkpoint file: {init_from}"))
    if issues:
        raise SpecError(issues)
    warnings = tuple(curriculum_warnings(path, agent, phases))
    return ResolvedCurriculum(path, spec, agent_file, agent, phases, demos_file, init_from, warnings)


def curriculum_warnings(path: Path, agent: AgentSpec, phases: list[CurriculumPhase]) -> list[str]:
    """Every warning of a curriculum, one line each, naming the file, phase and stage."""
    return hidden_goal_warnings(path, agent, phases) + rl2_warnings(path, agent, phases)


def rl2_warnings(path: Path, agent: AgentSpec, phases: list[CurriculumPhase]) -> list[str]:
    """An RL² agent with nothing to infer (the goal observable), or whose BPTT chunks never cross
    an episode boundary: trials start at chunk starts, and episodes that run to their limit E start
    at multiples of E, which all fall on chunk starts when `bptt_length` divides E, so no gradient
    ever carries what was learnt in one episode into the next."""
    if agent.algo != "rl2":
        return []
    lines = []
    bptt = agent.ppo.bptt_length
    for i, phase in enumerate(phases):
        task = phase.task
        where = f"{path}: phases[{i}] ({phase.task_file})"
        if task.goals.observable:
            lines.append(f"{where}: the goal is observable, so RL² has nothing to infer (meta-RL hides it: goals.observable: false)")
        aligned = sorted({n for n in phase.stages if bptt is not None and task.episode_steps(task.stage(n)) % bptt == 0})
        if aligned:
            lines.append(
                f"{where}: agent ppo.bptt_length {bptt} divides the episode length of stage {', '.join(aligned)}: every "
                "BPTT chunk then lies inside one episode and RL² cannot learn to carry what it found into the next "
                "episode; choose a bptt_length that does not divide it"
            )
    return lines


def hidden_goal_warnings(path: Path, agent: AgentSpec, phases: list[CurriculumPhase]) -> list[str]:
    """One line per stage where an agent that cannot infer a hidden goal trains on a stage whose
    success depends on it. Only RL² reads rewards, so only RL² can find a goal it does not see;
    any other agent (an LSTM included) can reach a held-out goal only by chance, or by memorising
    the train goals through whatever else the observation shows. A memoryless baseline for RL²
    is exactly that, so this is a warning, not an error."""
    if agent.algo == "rl2":
        return []
    lines = []
    for i, phase in enumerate(phases):
        task = phase.task
        if task.goals.observable or "goal_pos" not in backend_features(task):
            continue
        for stage in task.stages:
            needs = sorted({c.feature for c in stage.success.all} & GOAL_FEATURES)
            if stage.name in phase.stages and needs:
                lines.append(
                    f"{path}: phases[{i}] stage '{stage.name}' of {phase.task_file}: success depends on the goal "
                    f"({', '.join(needs)}) but goals.observable is false; a {agent.algo.upper()} agent does not see the "
                    "reward, so it cannot find a held-out goal: set goals.observable: true, or train with algo: rl2"
                )
    return lines


def _check_warm_start(
    spec: CurriculumSpec, path: Path, agent: AgentSpec, phases: list[CurriculumPhase], issues: list[SpecIssue]
) -> Path | None:
    """The warm start's phase, stage, demos file and agent; returns the demos path."""
    ws = spec.warm_start
    assert ws is not None
    if agent.algo == "rl2":
        msg = "a warm start clones single episodes; an RL² agent reads trials (previous action and reward inputs), which demos do not have"
        issues.append(SpecIssue(str(path), "warm_start", msg))
    if agent.algo == "mpc" and ws.dagger.rounds > 0:
        msg = f"algo: mpc has no policy to clone, so no DAgger student; expected 0 (got {ws.dagger.rounds}): its demos seed the model's data"
        issues.append(SpecIssue(str(path), "warm_start.dagger.rounds", msg))
    if agent.algo == "mpc" and ws.phase == "all" and ws.stage is None and len({p.stages[-1] for p in phases}) > 1:
        # the demos' rewards train the model's reward on one stage's rows (taskforge/agents/mpc.py)
        last = ", ".join(dict.fromkeys(p.stages[-1] for p in phases))
        msg = f"algo: mpc's demos are one stage's (their rewards train that stage's reward), but phase: all ends in several ({last}); name one"
        issues.append(SpecIssue(str(path), "warm_start.stage", msg))
    if ws.phase != "all" and ws.phase >= len(phases):
        msg = f"no phase {ws.phase}; expected an index below {len(phases)} (phases counts from 0) or 'all'"
        issues.append(SpecIssue(str(path), "warm_start.phase", msg))
    elif ws.stage is not None:
        for phase in phases if ws.phase == "all" else [phases[ws.phase]]:
            if ws.stage not in phase.task.stage_names:
                msg = f"no stage '{ws.stage}' in {phase.task_file}; {expected_one_of(ws.stage, phase.task.stage_names)}"
                issues.append(SpecIssue(str(path), "warm_start.stage", msg))
    if ws.demos is None:
        return None
    demos_file = resolve_relative(path, ws.demos)
    if not demos_file.is_file():
        issues.append(SpecIssue(str(path), "warm_start.demos", f"file not found: {demos_file}"))
    return demos_file


def _collect(issues: list[SpecIssue], loader, file: Path, parent: Path, field: str):
    """Run `loader(file)`; a missing file is reported at the referring field of `parent`."""
    if not file.is_file():
        issues.append(SpecIssue(str(parent), field, f"file not found: {file}"))
        return None
    try:
        return loader(file)
    except SpecError as exc:
        issues += exc.issues
        return None
