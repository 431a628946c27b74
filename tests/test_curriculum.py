"""The curriculum scheduler on scripted success streams: no simulator, no policy."""

from __future__ import annotations

import json

import numpy as np
import pytest

from taskforge.curriculum import Assignment, CurriculumScheduler, LearningProgressSampler
from taskforge.spec import CurriculumSpec


def make_spec(phases: list[dict], **rules) -> CurriculumSpec:
    """A curriculum of the given phases. Replay is off unless asked for, so scripted streams stay exact."""
    rules.setdefault("replay", {"fraction": 0.0})
    return CurriculumSpec.model_validate(
        {"name": "test", "agent": "agent.yaml", "total_steps": 10**9, "phases": phases, **rules}
    )


def make_scheduler(
    stages: list[list[str]],
    tasks: list[list[str]] | None = None,
    phase_overrides: list[dict] | None = None,
    seed: int = 0,
    **rules,
) -> CurriculumScheduler:
    tasks = tasks or [["env"] for _ in stages]
    overrides = phase_overrides or [{} for _ in stages]
    phases = [{"task": f"task{i}.yaml", "stages": s, **o} for i, (s, o) in enumerate(zip(stages, overrides))]
    return CurriculumScheduler(make_spec(phases, **rules), stages, tasks, seed=seed)


def current(scheduler: CurriculumScheduler, task: str = "env") -> Assignment:
    return Assignment(scheduler.phase, scheduler.stage, task, replay=False)


def feed(scheduler: CurriculumScheduler, outcomes, steps: int = 10) -> list:
    """Record `outcomes` as episodes of the current stage. Returns the events they caused."""
    events = []
    for success in outcomes:
        events += scheduler.record(current(scheduler), success, steps)
    return events


RULE = {"promotion": {"threshold": 0.8, "window": 10, "min_steps": 100}}


# --- promotion ----------------------------------------------------------------------------------


def test_promotes_when_window_full_threshold_met_and_min_steps_spent():
    scheduler = make_scheduler([["a", "b"]], **RULE)
    assert feed(scheduler, [True] * 9) == []  # 90 steps, window 9/10
    [event] = feed(scheduler, [True])
    assert (event.kind, event.from_stage, event.to_stage, event.step) == ("promote", "a", "b", 100)
    assert event.success_rate == 1.0
    assert (scheduler.phase, scheduler.stage, scheduler.finished) == (0, "b", False)


def test_no_promotion_until_window_full():
    scheduler = make_scheduler([["a", "b"]], **RULE)
    assert feed(scheduler, [True] * 9, steps=1000) == []  # steps and rate fine, window not full
    assert scheduler.stage == "a"
    assert len(feed(scheduler, [True], steps=1000)) == 1


def test_no_promotion_below_threshold_and_threshold_is_inclusive():
    scheduler = make_scheduler([["a", "b"]], **RULE)
    assert feed(scheduler, [False] * 3 + [True] * 7, steps=1000) == []  # 0.7 < 0.8
    [event] = feed(scheduler, [True], steps=1000)  # window is now 2 failures + 8 successes
    assert event.success_rate == pytest.approx(0.8)
    assert scheduler.stage == "b"


def test_no_promotion_until_min_steps_spent():
    scheduler = make_scheduler([["a", "b"]], promotion={"threshold": 0.8, "window": 10, "min_steps": 1000})
    assert feed(scheduler, [True] * 99) == []  # 990 steps, full window of successes
    [event] = feed(scheduler, [True])
    assert event.step == 1000


def test_without_min_steps_a_stage_already_mastered_passes_as_soon_as_the_window_fills():
    """A warm-started policy that already passes is not held back by a fixed minimum."""
    scheduler = make_scheduler([["a", "b", "c"]], promotion={"threshold": 0.8, "window": 5})
    assert feed(scheduler, [True] * 4) == []
    [event] = feed(scheduler, [True])
    assert (event.to_stage, event.step, event.reason) == ("b", 50, "threshold")


def test_a_stage_that_plateaus_is_passed_when_its_step_budget_is_spent():
    scheduler = make_scheduler([["a", "b"]], promotion={"threshold": 0.8, "window": 10, "max_steps": 300})
    assert feed(scheduler, [False, True] * 14) == []  # 280 steps at 0.5: below the threshold, budget left
    assert feed(scheduler, [True]) == []  # 290 steps
    [event] = feed(scheduler, [False])  # 300 steps: the budget is spent
    assert (event.kind, event.from_stage, event.to_stage, event.reason) == ("promote", "a", "b", "budget")
    assert event.step == 300 and event.success_rate == pytest.approx(0.5)
    assert scheduler.stage == "b"  # the budget restarts in the new stage
    assert feed(scheduler, [False] * 29) == []
    [last] = feed(scheduler, [False])
    assert (last.kind, last.reason, scheduler.finished) == ("finish", "budget", True)


def test_a_budget_below_the_minimum_is_refused():
    with pytest.raises(ValueError, match="'max_steps' \\(10\\) must be >= 'min_steps' \\(100\\)"):
        make_spec([{"task": "t.yaml"}], promotion={"min_steps": 100, "max_steps": 10})


def test_window_counts_only_the_last_episodes():
    scheduler = make_scheduler([["a", "b"]], promotion={"threshold": 1.0, "window": 3, "min_steps": 0})
    assert feed(scheduler, [False, True, True, False, True, True]) == []
    assert len(feed(scheduler, [True])) == 1


def test_phase_promotion_override_replaces_the_curriculum_rule():
    scheduler = make_scheduler(
        [["a"], ["b", "c"]],
        phase_overrides=[{}, {"promotion": {"threshold": 0.5, "window": 2, "min_steps": 0}}],
        **RULE,
    )
    feed(scheduler, [True] * 10)
    assert (scheduler.phase, scheduler.stage) == (1, "b")
    [event] = feed(scheduler, [True, False])
    assert (event.to_phase, event.to_stage, event.success_rate) == (1, "c", 0.5)


def test_promotes_across_phases_and_finishes_after_the_last_stage():
    scheduler = make_scheduler([["a", "b"], ["c"]], **RULE)
    events = feed(scheduler, [True] * 30)
    assert [(e.kind, e.from_phase, e.from_stage, e.to_phase, e.to_stage) for e in events] == [
        ("promote", 0, "a", 0, "b"),
        ("promote", 0, "b", 1, "c"),
        ("finish", 1, "c", 1, "c"),
    ]
    assert [e.step for e in events] == [100, 200, 300]
    assert scheduler.finished and (scheduler.phase, scheduler.stage) == (1, "c")
    assert scheduler.events == events
    # Training may go on at the last stage, but nothing moves any more.
    assert feed(scheduler, [True] * 20 + [False] * 20) == []
    assert scheduler.assign() == Assignment(1, "c", "env", False)


# --- demotion -----------------------------------------------------------------------------------

DEMOTION = {"enabled": True, "threshold": 0.2, "window": 5}


def test_demotes_one_stage_when_success_collapses_and_clears_windows():
    scheduler = make_scheduler([["a", "b", "c"]], demotion=DEMOTION, **RULE)
    feed(scheduler, [True] * 20)
    assert scheduler.stage == "c"
    assert feed(scheduler, [False] * 4) == []  # demotion window not full yet
    [event] = feed(scheduler, [False])
    assert (event.kind, event.from_stage, event.to_stage, event.success_rate) == ("demote", "c", "b", 0.0)
    assert scheduler.stage == "b"
    # b's old window held 10 successes; it was cleared on re-entry, so one success does not promote.
    assert feed(scheduler, [True]) == []
    assert feed(scheduler, [True] * 8) == []
    [event] = feed(scheduler, [True])
    assert (event.kind, event.to_stage) == ("promote", "c")
    # c's demotion window was cleared on re-entry too: four failures are not a full window.
    assert feed(scheduler, [False] * 4) == []


def test_demotion_needs_the_rate_below_threshold():
    scheduler = make_scheduler([["a", "b"]], demotion=DEMOTION, **RULE)
    feed(scheduler, [True] * 10)
    assert feed(scheduler, [True, False, False, False, False] * 4) == []  # 0.2 is not < 0.2
    assert len(feed(scheduler, [False])) == 1


def test_no_demotion_when_disabled():
    scheduler = make_scheduler([["a", "b"]], demotion={**DEMOTION, "enabled": False}, **RULE)
    feed(scheduler, [True] * 10)
    assert feed(scheduler, [False] * 100) == []
    assert scheduler.stage == "b"


def test_no_demotion_from_the_first_stage_of_a_phase():
    scheduler = make_scheduler([["a"], ["b", "c"]], demotion=DEMOTION, **RULE)
    assert feed(scheduler, [False] * 50) == []  # first stage of the first phase
    feed(scheduler, [True] * 10)
    assert (scheduler.phase, scheduler.stage) == (1, "b")
    assert feed(scheduler, [False] * 50) == []  # never back across the phase boundary
    assert (scheduler.phase, scheduler.stage) == (1, "b")


# --- replay and stale episodes ------------------------------------------------------------------


def test_replay_fraction_is_respected_and_uniform_over_passed_stages():
    scheduler = make_scheduler([["a", "b", "c"]], replay={"fraction": 0.2}, **RULE)
    first = [scheduler.assign() for _ in range(1000)]
    assert not any(a.replay for a in first) and {a.stage for a in first} == {"a"}

    feed(scheduler, [True] * 20)
    assert scheduler.stage == "c"
    assignments = [scheduler.assign() for _ in range(10_000)]
    replayed = [a for a in assignments if a.replay]
    assert len(replayed) / 10_000 == pytest.approx(0.2, abs=0.02)
    assert {a.stage for a in replayed} == {"a", "b"}
    assert sum(a.stage == "a" for a in replayed) / len(replayed) == pytest.approx(0.5, abs=0.05)
    assert all(a.stage == "c" for a in assignments if not a.replay)


def test_replay_reaches_back_into_earlier_phases():
    """In a later phase (e.g. a harder robot variant) replay also plays every stage of the earlier
    phases, so what the agent learnt there is not forgotten; the first position has none."""
    scheduler = make_scheduler([["a"], ["b"], ["c", "d"]], replay={"fraction": 0.5}, **RULE)
    assert not any(scheduler.assign().replay for _ in range(200))
    feed(scheduler, [True] * 10)
    assert (scheduler.phase, scheduler.stage) == (1, "b")
    replayed = [a for a in (scheduler.assign() for _ in range(400)) if a.replay]
    assert {(a.phase, a.stage) for a in replayed} == {(0, "a")}

    feed(scheduler, [True] * 20)
    assert (scheduler.phase, scheduler.stage) == (2, "d")
    assignments = [scheduler.assign() for _ in range(6000)]
    replayed = [a for a in assignments if a.replay]
    positions = [(a.phase, a.stage) for a in replayed]
    assert set(positions) == {(0, "a"), (1, "b"), (2, "c")}
    assert all(positions.count(p) / len(positions) == pytest.approx(1 / 3, abs=0.04) for p in set(positions))
    assert all((a.phase, a.stage) == (2, "d") for a in assignments if not a.replay)
    # replayed episodes of an earlier phase count in its statistics, never for the current stage
    assert scheduler.record(replayed[0], False, 10) == []
    assert scheduler.stage == "d"


def test_replayed_episodes_never_promote():
    scheduler = make_scheduler([["a", "b", "c"]], replay={"fraction": 0.5}, **RULE)
    feed(scheduler, [True] * 10)
    replay = Assignment(0, "a", "env", replay=True)
    assert all(scheduler.record(replay, True, 1000) == [] for _ in range(100))
    assert scheduler.stage == "b"
    assert scheduler.success_rates()["0/a"] == 1.0
    # Replayed steps did not count as time spent in b either.
    assert feed(scheduler, [True] * 9, steps=1) == []


def test_stale_episodes_count_in_statistics_but_never_promote():
    scheduler = make_scheduler([["a", "b"], ["c", "d"]], **RULE)
    stale = current(scheduler)  # a worker starts an episode of stage a ...
    feed(scheduler, [True] * 20)  # ... while others promote through a and b
    assert (scheduler.phase, scheduler.stage) == (1, "c")
    events = [scheduler.record(stale, True, 1000) for _ in range(50)]
    assert events == [[]] * 50 and scheduler.stage == "c"
    assert feed(scheduler, [False] * 5) == []
    assert scheduler.success_rates() == {"0/a": 1.0, "0/b": 1.0, "1/c": 0.0}


def test_record_rejects_assignments_the_curriculum_does_not_have():
    scheduler = make_scheduler([["a"]], tasks=[["x", "y"]])
    for bad in (Assignment(1, "a", "x", False), Assignment(0, "b", "x", False), Assignment(0, "a", "z", False)):
        with pytest.raises(ValueError):
            scheduler.record(bad, True, 1)


def test_constructor_checks_phases_stages_and_tasks():
    spec = make_spec([{"task": "t.yaml"}])
    with pytest.raises(ValueError, match="1 phases"):
        CurriculumScheduler(spec, [["a"], ["b"]], [["x"], ["y"]], seed=0)
    with pytest.raises(ValueError, match="empty"):
        CurriculumScheduler(spec, [[]], [["x"]], seed=0)
    with pytest.raises(ValueError, match="duplicate"):
        CurriculumScheduler(spec, [["a", "a"]], [["x"]], seed=0)


# --- sub-task sampling --------------------------------------------------------------------------

TASKS = ["solved", "hopeless", "learning"]


def train_three_tasks(scheduler: CurriculumScheduler) -> None:
    """'solved' always succeeds, 'hopeless' never does, 'learning' starts to succeed recently."""
    for i in range(1000):
        scheduler.record(current(scheduler, "solved"), True, 1)
        scheduler.record(current(scheduler, "hopeless"), False, 1)
        scheduler.record(current(scheduler, "learning"), i >= 950, 1)


def test_learning_progress_prefers_the_sub_task_whose_success_changes():
    scheduler = make_scheduler(
        [["solve"]], tasks=[TASKS], sampling={"mode": "learning_progress"}, promotion={"window": 10_000}
    )
    assert {scheduler.assign().task for _ in range(300)} == set(TASKS)  # no progress yet: uniform
    train_three_tasks(scheduler)
    counts = {task: 0 for task in TASKS}
    for _ in range(10_000):
        counts[scheduler.assign().task] += 1
    assert counts["learning"] > 8_500
    # The ε floor (0.1 / 3 each) keeps flat sub-tasks alive.
    assert 200 < counts["solved"] < 600 and 200 < counts["hopeless"] < 600


def test_phase_sampling_override_is_used():
    scheduler = make_scheduler(
        [["solve"], ["solve"]],
        tasks=[TASKS, TASKS],
        phase_overrides=[{"sampling": {"mode": "learning_progress"}}, {}],
        promotion={"window": 10_000},
    )
    train_three_tasks(scheduler)
    assert sum(scheduler.assign().task == "learning" for _ in range(1000)) > 850

    uniform = make_scheduler(
        [["solve"]],
        tasks=[TASKS],
        sampling={"mode": "learning_progress"},
        phase_overrides=[{"sampling": {"mode": "uniform"}}],
        promotion={"window": 10_000},
    )
    train_three_tasks(uniform)
    assert sum(uniform.assign().task == "learning" for _ in range(3000)) == pytest.approx(1000, abs=150)


def test_learning_progress_sampler_floor_and_flat_start():
    sampler = LearningProgressSampler(4, epsilon=0.2)
    assert np.allclose(sampler.probabilities(), 0.25)
    for _ in range(30):
        sampler.update(0, True)
    probabilities = sampler.probabilities()
    assert probabilities.sum() == pytest.approx(1.0)
    assert np.allclose(probabilities[1:], 0.2 / 4)
    assert probabilities[0] == pytest.approx(0.8 + 0.05)


def test_learning_progress_is_uniform_once_every_sub_task_has_settled():
    # MT10 from scratch: two sub-tasks solved long ago, eight never solved. Their LPs are leftovers
    # of the slow average's approach to 1 (~1e-5) and exact zeros; proportional sampling of those
    # leftovers gave the two solved sub-tasks 92 % of all episodes.
    sampler = LearningProgressSampler(10)
    for _ in range(1500):
        sampler.update(0, True)
        sampler.update(5, True)
        for task in (1, 2, 3, 4, 6, 7, 8, 9):
            sampler.update(task, False)
    assert 0.0 < sampler.learning_progress().max() < 1e-3
    assert np.allclose(sampler.probabilities(), 0.1)
    # One sub-task starting to move by the floor brings LP sampling back.
    for _ in range(3):
        sampler.update(7, True)
    probabilities = sampler.probabilities()
    assert probabilities[7] > 0.9 and np.allclose(np.delete(probabilities, 7), 0.1 / 10, atol=1e-3)


def test_success_rates_per_stage_and_sub_task():
    scheduler = make_scheduler([["solve"]], tasks=[["x", "y"]], promotion={"window": 4})
    for task, success in [("x", True), ("y", True), ("x", False), ("x", True), ("x", True), ("y", False)]:
        scheduler.record(current(scheduler, task), success, 1)
    # Windows hold the last 4 episodes (the promotion window), per stage and per sub-task.
    assert scheduler.success_rates() == {"0/solve": 0.5, "0/solve/x": 0.75, "0/solve/y": 0.5}

    single = make_scheduler([["solve"]])
    feed(single, [True])
    assert single.success_rates() == {"0/solve": 1.0}  # no per-sub-task key for a single env


# --- determinism and checkpoints ----------------------------------------------------------------

STAGES = [["reach", "push"], ["solve", "refine"]]
SUBTASKS = [["push-v3"], ["reach-v3", "push-v3", "pick-place-v3"]]


def full_scheduler(seed: int) -> CurriculumScheduler:
    """Every feature at once: replay, demotion, learning progress, a phase override."""
    return make_scheduler(
        STAGES,
        tasks=SUBTASKS,
        phase_overrides=[{}, {"sampling": {"mode": "learning_progress"}}],
        seed=seed,
        promotion={"threshold": 0.7, "window": 8, "min_steps": 50},
        demotion={"enabled": True, "threshold": 0.3, "window": 6},
        replay={"fraction": 0.3},
    )


# Probability of success per stage (plus a bonus per sub-task), so the stream depends on what was
# assigned. "refine" is hard: it is demoted several times before it finishes after ~200 episodes.
SKILL = {"reach": 0.9, "push": 0.8, "solve": 0.75, "refine": 0.2}
NOISE = np.random.default_rng(1234).random(4000)


def drive(scheduler: CurriculumScheduler, start: int, stop: int) -> tuple[list, list]:
    """Episodes start..stop-1, as one worker would: assign, play, record."""
    assignments, events = [], []
    for i in range(start, stop):
        assignment = scheduler.assign()
        bonus = 0.1 * SUBTASKS[assignment.phase].index(assignment.task)
        success = bool(NOISE[i] < SKILL[assignment.stage] + bonus)
        assignments.append(assignment)
        events += scheduler.record(assignment, success, 7 + i % 5)
    return assignments, events


def test_same_seed_gives_the_same_decisions():
    first, second, other = full_scheduler(7), full_scheduler(7), full_scheduler(8)
    run = drive(first, 0, 2000)
    assert run == drive(second, 0, 2000)
    assert run[0] != drive(other, 0, 2000)[0]
    assert {event.kind for event in run[1]} == {"promote", "demote", "finish"}


@pytest.mark.parametrize("split", [30, 100, 1500])  # in phase 1 before/among the demotions, after finish
def test_state_dict_survives_json_and_continues_identically(split: int):
    reference = full_scheduler(7)
    drive(reference, 0, split)
    state = json.loads(json.dumps(reference.state_dict()))

    restored = full_scheduler(99)  # a different seed: everything must come from the state
    restored.load_state_dict(state)
    assert restored.events == reference.events
    assert restored.success_rates() == reference.success_rates()
    position = (restored.phase, restored.stage, restored.finished)
    assert position == (reference.phase, reference.stage, reference.finished)
    assert drive(restored, split, 4000) == drive(reference, split, 4000)
    assert restored.state_dict() == reference.state_dict()


def test_load_state_dict_rejects_another_curriculum():
    state = full_scheduler(0).state_dict()
    other = make_scheduler([["reach"]], tasks=[["push-v3"]])
    with pytest.raises(ValueError, match="other phases"):
        other.load_state_dict(state)
    with pytest.raises(ValueError, match="version"):
        full_scheduler(0).load_state_dict({**state, "version": 0})


def test_reweighted_learning_progress_prefers_the_task_whose_success_is_low_and_rising():
    """Two sub-tasks with the same raw progress (success up by 0.1): one climbing from 0.1, one
    from 0.85. Plain LP splits the episodes evenly; with the paper's p_θ = 0.1 the low one gets
    most of them."""
    def climbing(reweight):
        sampler = LearningProgressSampler(2, epsilon=0.1, reweight=reweight)
        sampler.load_state_dict({"fast": [0.2, 0.95], "slow": [0.1, 0.85]})
        return sampler
    assert np.allclose(climbing(None).probabilities(), 0.5)
    low, high = climbing(0.1).probabilities()
    assert low > 0.8 and high < 0.2 and low + high == pytest.approx(1.0)
    assert np.allclose(climbing(0.5).probabilities(), 0.5)  # θ = 1/2 is the identity
    with pytest.raises(ValueError, match="reweight"):
        LearningProgressSampler(2, reweight=0.7)


def test_the_scheduler_reweights_progress_toward_low_success_when_asked():
    """'low' climbs 0 → 0.3 and 'high' 0.7 → 1.0 over their last 100 episodes: the same raw
    progress, so plain LP shares the episodes; `reweight: 0.1` gives most to 'low'. A reweight
    without learning-progress sampling is refused."""
    def share_of_low(sampling: dict) -> float:
        scheduler = make_scheduler([["solve"]], tasks=[["low", "high"]], sampling=sampling, promotion={"window": 10_000})
        for i in range(1000):
            late = i >= 900
            scheduler.record(current(scheduler, "low"), late and i % 10 in (1, 4, 7), 1)
            scheduler.record(current(scheduler, "high"), late or i % 10 < 7, 1)
        return sum(scheduler.assign().task == "low" for _ in range(2000)) / 2000
    assert 0.3 < share_of_low({"mode": "learning_progress"}) < 0.7
    assert share_of_low({"mode": "learning_progress", "reweight": 0.1}) > 0.75
    with pytest.raises(ValueError, match="'reweight' applies to mode 'learning_progress' only"):
        make_spec([{"task": "t.yaml"}], sampling={"mode": "uniform", "reweight": 0.1})


def test_sampling_probabilities_say_where_the_next_episodes_go():
    scheduler = make_scheduler([["solve"]], tasks=[TASKS], sampling={"mode": "learning_progress"}, promotion={"window": 10_000})
    train_three_tasks(scheduler)
    probabilities = scheduler.sampling_probabilities()
    assert set(probabilities) == {f"0/solve/{t}" for t in TASKS} and sum(probabilities.values()) == pytest.approx(1.0)
    assert max(probabilities, key=probabilities.get) == "0/solve/learning"
    assert make_scheduler([["solve"]], tasks=[TASKS]).sampling_probabilities() == {}  # uniform: nothing to report
