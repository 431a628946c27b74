"""The curriculum scheduler: which stage and sub-task the next episode runs, and when to move on.

It is a small state machine over (phase, stage) positions, fed only with finished episodes
(success, length). It knows nothing about simulators or policies, so the trainer can drive it from
any number of workers and tests can drive it from scripted success streams.

Semantics (the trainer relies on these):
- Promotion: the current stage is passed when its promotion window (the last `window` episodes
  *assigned to it as the current stage*) is full, its success rate is ≥ `threshold`, and at least
  `min_steps` env steps of those episodes were spent in it since it was (re-)entered (reason
  `threshold`); or, with `max_steps`, when that many steps were spent in it without passing
  (reason `budget`: a stage that plateaus below the threshold does not hold the run). The phase's
  own promotion rule replaces the curriculum-wide one. Passing the last stage of a phase enters the
  next phase's first stage. Passing the very last stage sets `finished` and freezes the position:
  training may go on there, but nothing promotes or demotes any more.
- Demotion (if enabled): when the demotion window of a stage that is not the first of its phase is
  full and its success rate is < `demotion.threshold`, go back one stage. Demotion never crosses
  a phase boundary. Promotion is checked before demotion.
- Entering a stage (by promotion or demotion) clears its promotion and demotion windows and its
  step count, so every decision is based only on episodes played since then.
- Replay: with probability `replay.fraction`, an assignment picks one of the positions already
  passed (uniformly: every stage of the earlier phases, then the current phase's earlier stages)
  instead of the current one, so neither an earlier stage nor an earlier phase's task (e.g. a
  robot variant) is forgotten. There is no replay at the very first position.
- Only current-stage episodes decide. Replayed episodes (`replay=True`) and stale ones count only
  in statistics: `success_rates()` and the sub-task learning-progress EMAs. A stale episode was
  assigned a stage or phase that is no longer current, e.g. by a worker that started it before a
  promotion. Episodes are matched to the current stage by (phase, stage) name. So an episode
  started before a demotion out of stage B, and finished after a re-promotion into B, counts for
  B. That is at most one episode per worker, played on B anyway.
- Event `step` is the number of env steps of all episodes recorded so far (including replayed
  and stale ones), i.e. the scheduler's own clock. Episodes still running are not counted.

Determinism: every random choice draws from one `numpy.random.Generator` seeded at construction
and saved in `state_dict()`. The same seed and the same sequence of `assign`/`record` calls give
the same decisions. The scheduler is not thread-safe: call it from one thread, in a deterministic
order, if runs must be reproducible.
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np

from taskforge.curriculum.progress import LearningProgressSampler
from taskforge.spec import CurriculumSpec

STATE_VERSION = 1

EventKind = Literal["promote", "demote", "finish"]
EventReason = Literal["threshold", "budget"]


@dataclass(frozen=True)
class Assignment:
    """What one episode runs. Hand it back unchanged to `record`. The scheduler uses it to tell a
    current-stage episode from a replayed or stale one."""

    phase: int
    stage: str
    task: str
    replay: bool


@dataclass(frozen=True)
class CurriculumEvent:
    """A change of position. `success_rate` is the window rate that triggered it (for a `budget`
    move, the rate of the partly filled window). A `finish` event has the last stage as both
    `from` and `to`. `reason` says whether the threshold was met or the stage's step budget spent."""

    kind: EventKind
    step: int
    from_phase: int
    from_stage: str
    to_phase: int
    to_stage: str
    success_rate: float
    reason: EventReason = "threshold"


def _rate(window: deque[bool]) -> float:
    return sum(window) / len(window)


def _index(names: list[str], what: str) -> dict[str, int]:
    if not names:
        raise ValueError(f"{what}: the list is empty")
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ValueError(f"{what}: duplicate names {duplicates}")
    return {name: i for i, name in enumerate(names)}


class CurriculumScheduler:
    """Walks the phases and stages of a `CurriculumSpec`. Call `assign()` for each new episode and
    `record()` for each finished one."""

    def __init__(
        self,
        spec: CurriculumSpec,
        phase_stages: list[list[str]],
        phase_tasks: list[list[str]],
        seed: int,
    ):
        if not len(spec.phases) == len(phase_stages) == len(phase_tasks):
            raise ValueError(
                f"the curriculum has {len(spec.phases)} phases, but got stages for {len(phase_stages)} "
                f"and sub-tasks for {len(phase_tasks)}"
            )
        self._spec = spec
        self._stages = [list(stages) for stages in phase_stages]
        self._tasks = [list(tasks) for tasks in phase_tasks]
        self._stage_index = [_index(s, f"phase {p} stages") for p, s in enumerate(self._stages)]
        self._task_index = [_index(t, f"phase {p} sub-tasks") for p, t in enumerate(self._tasks)]
        self._promotion = [phase.promotion or spec.promotion for phase in spec.phases]
        self._rng = np.random.default_rng(seed)

        # Learning-progress samplers exist per (phase, stage). Each stage has its own success
        # criterion, so the progress of one stage says nothing about another. A phase with a single
        # sub-task needs no sampler.
        self._samplers: list[list[LearningProgressSampler | None]] = [
            [
                LearningProgressSampler(len(tasks), reweight=sampling.reweight)
                if sampling.mode == "learning_progress" and len(tasks) > 1
                else None
                for _ in stages
            ]
            for sampling, stages, tasks in zip(
                (phase.sampling or spec.sampling for phase in spec.phases), self._stages, self._tasks
            )
        ]
        # Statistics windows, kept across re-entries: every recorded episode of a stage, replayed
        # or stale included, and the same per sub-task. Sized like the phase's promotion window.
        self._stage_stats = [
            [deque(maxlen=rule.window) for _ in stages] for rule, stages in zip(self._promotion, self._stages)
        ]
        self._task_stats = [
            [[deque(maxlen=rule.window) for _ in tasks] for _ in stages]
            for rule, stages, tasks in zip(self._promotion, self._stages, self._tasks)
        ]

        self._events: list[CurriculumEvent] = []
        self._total_steps = 0
        self._finished = False
        self._enter(0, 0)

    # --- position -------------------------------------------------------------------------------

    @property
    def phase(self) -> int:
        return self._phase

    @property
    def stage(self) -> str:
        return self._stages[self._phase][self._stage]

    @property
    def finished(self) -> bool:
        return self._finished

    def task_names(self, phase: int) -> list[str]:
        """The sub-tasks of a phase's task (one name for a single task)."""
        return list(self._tasks[phase])

    @property
    def events(self) -> list[CurriculumEvent]:
        """Every promotion, demotion and the finish so far, oldest first (a copy)."""
        return list(self._events)

    def _enter(self, phase: int, stage: int) -> None:
        self._phase, self._stage = phase, stage
        self._promotion_window: deque[bool] = deque(maxlen=self._promotion[phase].window)
        self._demotion_window: deque[bool] = deque(maxlen=self._spec.demotion.window)
        self._stage_steps = 0

    # --- assigning episodes ---------------------------------------------------------------------

    def assign(self) -> Assignment:
        """The phase, stage and sub-task the next episode of a worker should run."""
        phase, stage = self._phase, self._stage
        passed = self._passed()
        fraction = self._spec.replay.fraction
        replay = bool(passed) and fraction > 0.0 and bool(self._rng.random() < fraction)
        if replay:
            phase, stage = passed[int(self._rng.integers(len(passed)))]
        task = self._pick_task(phase, stage)
        return Assignment(phase, self._stages[phase][stage], self._tasks[phase][task], replay)

    def _passed(self) -> list[tuple[int, int]]:
        """The (phase, stage) positions behind the current one, in curriculum order."""
        earlier = [(p, s) for p in range(self._phase) for s in range(len(self._stages[p]))]
        return earlier + [(self._phase, s) for s in range(self._stage)]

    def _pick_task(self, phase: int, stage: int) -> int:
        count = len(self._tasks[phase])
        if count == 1:
            return 0
        sampler = self._samplers[phase][stage]
        if sampler is not None:
            return sampler.sample(self._rng)
        return int(self._rng.integers(count))

    # --- recording episodes ---------------------------------------------------------------------

    def record(self, assignment: Assignment, success: bool, steps: int) -> list[CurriculumEvent]:
        """An episode of `assignment` finished after `steps` env steps. Returns the events it caused."""
        if steps < 0:
            raise ValueError(f"an episode cannot have {steps} steps")
        phase, stage, task = self._locate(assignment)
        success = bool(success)
        self._total_steps += steps
        self._stage_stats[phase][stage].append(success)
        self._task_stats[phase][stage][task].append(success)
        sampler = self._samplers[phase][stage]
        if sampler is not None:
            sampler.update(task, success)

        if self._finished or assignment.replay or (phase, stage) != (self._phase, self._stage):
            return []
        self._stage_steps += steps
        self._promotion_window.append(success)
        self._demotion_window.append(success)
        event = self._try_promote() or self._try_demote()
        return [event] if event is not None else []

    def _locate(self, assignment: Assignment) -> tuple[int, int, int]:
        phase = assignment.phase
        if not 0 <= phase < len(self._stages):
            raise ValueError(f"assignment of phase {phase}, but the curriculum has {len(self._stages)} phases")
        stage = self._stage_index[phase].get(assignment.stage)
        if stage is None:
            raise ValueError(f"phase {phase} has no stage {assignment.stage!r}; it has {self._stages[phase]}")
        task = self._task_index[phase].get(assignment.task)
        if task is None:
            raise ValueError(f"phase {phase} has no sub-task {assignment.task!r}; it has {self._tasks[phase]}")
        return phase, stage, task

    def _try_promote(self) -> CurriculumEvent | None:
        rule = self._promotion[self._phase]
        window = self._promotion_window
        passed = len(window) >= rule.window and self._stage_steps >= rule.min_steps and _rate(window) >= rule.threshold
        over_budget = rule.max_steps is not None and self._stage_steps >= rule.max_steps
        if not (passed or over_budget):
            return None
        rate, reason = _rate(window), "threshold" if passed else "budget"
        if self._stage + 1 < len(self._stages[self._phase]):
            return self._move("promote", self._phase, self._stage + 1, rate, reason)
        if self._phase + 1 < len(self._stages):
            return self._move("promote", self._phase + 1, 0, rate, reason)
        self._finished = True
        return self._move("finish", self._phase, self._stage, rate, reason)

    def _try_demote(self) -> CurriculumEvent | None:
        rule = self._spec.demotion
        window = self._demotion_window
        if not rule.enabled or self._stage == 0 or len(window) < rule.window:
            return None
        rate = _rate(window)
        if rate >= rule.threshold:
            return None
        return self._move("demote", self._phase, self._stage - 1, rate)

    def _move(self, kind: EventKind, phase: int, stage: int, rate: float, reason: EventReason = "threshold") -> CurriculumEvent:
        event = CurriculumEvent(
            kind=kind,
            step=self._total_steps,
            from_phase=self._phase,
            from_stage=self.stage,
            to_phase=phase,
            to_stage=self._stages[phase][stage],
            success_rate=rate,
            reason=reason,
        )
        self._events.append(event)
        if kind != "finish":
            self._enter(phase, stage)
        return event

    # --- logging --------------------------------------------------------------------------------

    def success_rates(self) -> dict[str, float]:
        """Success over the last promotion-window-many recorded episodes (replayed and stale
        included). Keys are "phase/stage" and, for task sets, "phase/stage/sub-task". Only
        stages and sub-tasks with at least one episode are listed."""
        rates: dict[str, float] = {}
        for phase, stages in enumerate(self._stages):
            for stage, stage_name in enumerate(stages):
                window = self._stage_stats[phase][stage]
                if window:
                    rates[f"{phase}/{stage_name}"] = _rate(window)
                if len(self._tasks[phase]) == 1:
                    continue
                for task, task_name in enumerate(self._tasks[phase]):
                    window = self._task_stats[phase][stage][task]
                    if window:
                        rates[f"{phase}/{stage_name}/{task_name}"] = _rate(window)
        return rates

    def sampling_probabilities(self) -> dict[str, float]:
        """Where learning-progress sampling sends the current stage's next episodes: keys
        "phase/stage/sub-task", one per sub-task; empty when the current stage samples uniformly.
        Logged so a run shows which sub-tasks got the episodes, not only how well each did."""
        sampler = self._samplers[self._phase][self._stage]
        if sampler is None:
            return {}
        prefix = f"{self._phase}/{self.stage}"
        return {f"{prefix}/{name}": float(p) for name, p in zip(self._tasks[self._phase], sampler.probabilities())}

    # --- checkpointing --------------------------------------------------------------------------

    def state_dict(self) -> dict:
        """Everything needed to continue identically. It holds only lists, dicts, numbers, strings
        and booleans, so it survives `json.dumps`/`json.loads`. The generator state holds 128-bit
        integers, which Python's json keeps exact."""
        return {
            "version": STATE_VERSION,
            "stages": [list(stages) for stages in self._stages],
            "tasks": [list(tasks) for tasks in self._tasks],
            "rng": self._rng.bit_generator.state,
            "phase": self._phase,
            "stage": self._stage,
            "finished": self._finished,
            "total_steps": self._total_steps,
            "stage_steps": self._stage_steps,
            "promotion_window": [int(s) for s in self._promotion_window],
            "demotion_window": [int(s) for s in self._demotion_window],
            "stage_stats": [[[int(s) for s in w] for w in phase] for phase in self._stage_stats],
            "task_stats": [
                [[[int(s) for s in w] for w in stage] for stage in phase] for phase in self._task_stats
            ],
            "samplers": [
                [sampler.state_dict() if sampler is not None else None for sampler in phase]
                for phase in self._samplers
            ],
            "events": [asdict(event) for event in self._events],
        }

    def load_state_dict(self, state: dict) -> None:
        """Restore a `state_dict()` into a scheduler built with the same stages and sub-tasks. If the
        spec changed, the state is adapted: windows are cut to the new sizes, and a phase that switched
        to learning_progress starts with fresh EMAs."""
        if state.get("version") != STATE_VERSION:
            raise ValueError(f"curriculum state version {state.get('version')!r}, expected {STATE_VERSION}")
        if state["stages"] != self._stages or state["tasks"] != self._tasks:
            raise ValueError(
                "the curriculum state was saved for other phases, stages or sub-tasks: "
                f"stages {state['stages']} / sub-tasks {state['tasks']}, this scheduler has "
                f"{self._stages} / {self._tasks}"
            )
        self._rng.bit_generator.state = state["rng"]
        self._enter(state["phase"], state["stage"])
        self._finished = bool(state["finished"])
        self._total_steps = int(state["total_steps"])
        self._stage_steps = int(state["stage_steps"])
        self._promotion_window.extend(bool(s) for s in state["promotion_window"])
        self._demotion_window.extend(bool(s) for s in state["demotion_window"])
        for windows, saved in zip(self._stage_stats, state["stage_stats"]):
            for window, outcomes in zip(windows, saved):
                window.clear()
                window.extend(bool(s) for s in outcomes)
        for stages, saved_stages in zip(self._task_stats, state["task_stats"]):
            for windows, saved in zip(stages, saved_stages):
                for window, outcomes in zip(windows, saved):
                    window.clear()
                    window.extend(bool(s) for s in outcomes)
        for samplers, saved in zip(self._samplers, state["samplers"]):
            for sampler, sampler_state in zip(samplers, saved):
                if sampler is not None and sampler_state is not None:
                    sampler.load_state_dict(sampler_state)
        self._events = [CurriculumEvent(**event) for event in state["events"]]
