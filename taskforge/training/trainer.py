"""`taskforge train`: PPO along a curriculum, with logs, atomic checkpoints and resume.

Reading order: `train()` reads top to bottom. `_start()` decides what this call continues
(a checkpoint, or nothing) and checks every input before any file is written; `_Session` holds
what the loop works on (agent, scheduler, envs, logger) and does one thing per method: run one
update, log it, switch phase, evaluate, checkpoint.
"""

from __future__ import annotations

import copy
import signal
import sys
import time
from dataclasses import asdict, dataclass
from functools import partial
from itertools import groupby
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector import VectorEnv
from pydantic import BaseModel, ValidationError
from tqdm import tqdm

from taskforge.agents import Agent, WeightsMismatch, make_vector_env, set_torch_threads, wrap_for_training
from taskforge.curriculum import CurriculumScheduler
from taskforge.envs import PhasedEnv, ResolvedCurriculum, load_curriculum
from taskforge.rollouts import StageResult, evaluate_rows, summarize
from taskforge.run import RunDir, build_agent, load_checkpoint, policy_file, save_checkpoint, save_json
from taskforge.spec import AgentSpec, SpecError, TaskSpec
from taskforge.training.driver import CurriculumDriver, EpisodeStats
from taskforge.training.metrics import MetricsLogger
from taskforge.training.warm_start import prepare_warm_start


class Interrupted(Exception):
    """Training stopped by Ctrl-C or SIGTERM after saving a checkpoint."""

    def __init__(self, step: int, run_dir: Path, discarded: int = 0):
        lost = (f" (the {discarded:,} steps collected since were not yet learnt from and are discarded)"
                if discarded else "")
        super().__init__(f"interrupted at step {step:,}{lost}; checkpoint saved in {run_dir} (continue with --resume)")
        self.step = step


def run_config(cur: ResolvedCurriculum, seed: int, total_steps: int) -> dict[str, Any]:
    """Everything needed to rebuild the run's envs and agent without the original files."""
    return {
        "curriculum_file": str(cur.file),
        "curriculum": cur.spec.model_dump(mode="json"),
        "agent": cur.agent.model_dump(mode="json"),
        "phases": [
            {"task_file": str(p.task_file), "task": p.task.model_dump(mode="json"), "stages": p.stages}
            for p in cur.phases
        ],
        "seed": seed,
        "total_steps": total_steps,
    }


def train(
    curriculum_file: str | Path,
    run_dir: str | Path | None = None,
    seed: int | None = None,
    steps: int | None = None,
    resume: bool = False,
    progress: bool = True,
    stop_at: int | None = None,
) -> Path:
    """Train along a curriculum; returns the run directory. Raises `SpecError` for bad input
    (before writing anything) and `Interrupted` after saving a checkpoint on Ctrl-C/SIGTERM.

    `steps` is the run's length: it sets the learning-rate schedule and is stored with the run.
    `stop_at` pauses earlier (checkpoint, no final policy) so that a long run can be split into
    jobs; the schedule still spans `steps`, which a chunked `steps` on every resume would not
    (each chunk would anneal the learning rate to zero). `resume` on a run that has no
    checkpoint yet (killed before its first) starts it afresh, so a script may always pass it."""
    cur = load_curriculum(curriculum_file)
    for warning in cur.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    run = RunDir(run_dir or Path("runs") / f"{cur.spec.name}-seed{cur.spec.seed if seed is None else seed}")
    start = _start(cur, run, seed, steps, resume)

    set_torch_threads(cur.agent.runtime)
    agent, shapes = build_agent(cur.agent, [(p.task, p.task_file) for p in cur.phases], start.seed, cur.file, cur.agent_file)
    scheduler = CurriculumScheduler(cur.spec, [p.stages for p in cur.phases], shapes.task_names, start.seed)
    if start.state:
        agent.load_state_dict(start.state["agent"])
        scheduler.load_state_dict(start.state["curriculum"])
    elif cur.init_from is not None:
        load_init_from(cur, agent, start.seed)
    # demos: pretraining (fresh runs only) and PPO's decaying BC term; writes no file yet
    warm = prepare_warm_start(cur, agent, run, start.seed, resumed=start.state is not None, progress=progress)

    # every input is good: from here on the run directory is written
    run.path.mkdir(parents=True, exist_ok=True)
    run.remove_stale_temporaries()
    save_json(start.config, run.config)
    session = _Session(cur, run, start, agent, scheduler, progress)
    if start.state is None:
        for warning in cur.warnings:
            session.logger.event({"step": agent.global_step, "kind": "warning", "message": warning})
    if warm is not None:
        if warm.metrics is not None:  # evaluate right after pretraining: the curve starts where the demos left it
            warm.metrics.update(session.evaluation_row("after pretraining"))
        warm.record(run, session.logger)
    if start.state is None and cur.init_from is not None:  # the curve starts where the loaded weights stand on this curriculum
        session.logger.log(0, session.evaluation_row(f"from {cur.init_source(start.seed).name}"))
    session.run(until=start.total if stop_at is None else min(start.total, stop_at))
    return run.path


# ------------------------------------------------------------------------------ start or resume


@dataclass
class _Start:
    seed: int
    total: int
    config: dict[str, Any]
    state: dict[str, Any] | None
    """The checkpoint this call continues, or None for a fresh run."""


def _start(cur: ResolvedCurriculum, run: RunDir, seed: int | None, steps: int | None, resume: bool) -> _Start:
    """What this call continues; every refusal is a `SpecError` before anything is written."""
    state = None
    if resume and run.checkpoint.is_file():
        state = load_checkpoint(run.checkpoint)
        stored = state["config"]
        if not (_same_spec(stored["curriculum"], cur.spec) and _same_spec(stored["agent"], cur.agent)):
            raise SpecError.single(
                cur.file, "", f"differs from the curriculum/agent of the run in {run} (see its {run.config.name}); "
                "resume with the same files or start a new --run-dir",
            )
        if seed is not None and seed != stored["seed"]:
            raise SpecError.single(run.path, "", f"was started with --seed {stored['seed']}; resume without --seed or with the same one")
        seed = stored["seed"]
    elif resume:
        if run.final.is_file():
            raise SpecError.single(run.path, "", f"holds a finished run ({run.final.name}) and no {run.checkpoint.name} to continue")
        print(f"note: no {run.checkpoint.name} in {run} yet (stopped before its first checkpoint, or never started): "
              "starting the run afresh", file=sys.stderr)
    elif run.checkpoint.exists() or run.final.exists():
        held = run.checkpoint if run.checkpoint.exists() else run.final
        raise SpecError.single(run.path, "", f"already holds a run ({held.name}); pass --resume to continue it or choose another --run-dir")
    seed = cur.spec.seed if seed is None else seed
    total = steps or (state["config"]["total_steps"] if state else cur.spec.total_steps)
    return _Start(seed, total, run_config(cur, seed, total), state)


def load_init_from(cur: ResolvedCurriculum, agent: Agent, seed: int) -> None:
    """`agent` (fresh, built for `cur`) takes the learnt weights of the run `cur`'s `init_from`
    names for the run of `seed`. A run without a policy yet, an unreadable file or weights that do
    not fit are one `SpecError` at `init_from`, raised before anything is written (`validate`
    calls this too, at the curriculum's seed)."""
    assert cur.init_from is not None
    try:
        source = policy_file(cur.init_source(seed))
        state = load_checkpoint(source)
    except SpecError as exc:
        raise SpecError.single(cur.file, "init_from", str(exc.issues[0])) from None
    try:
        agent.load_weights(state["agent"])
    except WeightsMismatch as exc:
        raise SpecError.single(cur.file, "init_from", f"{source} does not fit this curriculum's agent: {exc} "
                               "(expected a run of the same algo, network sizes and observation)") from None


# ------------------------------------------------------------------------------ the loop


def _same_spec(stored: dict[str, Any], current: BaseModel) -> bool:
    """Whether a checkpoint's stored spec is `current`, compared after reading it with today's
    schema: a field added to the schema since the run started (with its default) must not stop
    the run from resuming. A stored spec today's schema rejects is a different one."""
    try:
        return type(current).model_validate(stored).model_dump(mode="json") == current.model_dump(mode="json")
    except ValidationError:
        return False


def _train_env(phases: list[tuple[TaskSpec, str]], phase: int, privileged: bool, agent: AgentSpec) -> gymnasium.Env:
    """One worker's env: every phase's task on the train goals (`PhasedEnv`: the curriculum says
    which phase each episode plays, replay included), in trials for RL²."""
    return wrap_for_training(PhasedEnv(phases, split="train", privileged=privileged, phase=phase), agent)


class _Session:
    """One call of `train` from its first update to its last: the loop and what it works on."""

    def __init__(self, cur: ResolvedCurriculum, run: RunDir, start: _Start, agent: Agent,
                 scheduler: CurriculumScheduler, progress: bool):
        self.cur, self.run_dir, self.agent, self.scheduler = cur, run, agent, scheduler
        self.seed, self.total, self.config = start.seed, start.total, start.config
        self.logger = MetricsLogger(run, resume_step=agent.global_step if start.state else None, fresh=start.state is None)
        self.progress = progress
        self.bar: tqdm | None = None
        self.collected = 0
        """Env steps of the rollout in progress (not yet learnt from)."""
        self.last_eval: tuple[int, list[tuple[int, str, str | None]], list[StageResult]] | None = None
        self.last_good = self.snapshot()  # what a Ctrl-C saves: the state after the last complete update

    def say(self, line: str) -> None:
        """A progress line, prefixed with the step: through the bar when there is one (it keeps
        the bar below the line), printed either way, so logs of `--no-progress` runs have them."""
        line = f"[{self.agent.global_step:,}] {line}"
        if self.bar is not None:
            self.bar.write(line, file=sys.stderr)
        else:
            print(line, file=sys.stderr)

    def snapshot(self) -> dict[str, Any]:
        return copy.deepcopy({"config": self.config, "agent": self.agent.state_dict(), "curriculum": self.scheduler.state_dict()})

    def build_envs(self) -> tuple[VectorEnv, CurriculumDriver]:
        """The training envs: each worker can play every phase, so a new phase needs no new envs
        and replay reaches back into earlier phases."""
        phase = self.cur.phases[self.scheduler.phase]
        self.say(f"starting {self.cur.agent.ppo.num_envs} envs at phase {self.scheduler.phase} ({phase.task_file})")
        phases = [(p.task, str(p.task_file)) for p in self.cur.phases]
        fn = partial(_train_env, phases, self.scheduler.phase, self.cur.agent.asymmetric_critic, self.cur.agent)
        envs = make_vector_env([fn] * self.cur.agent.ppo.num_envs, self.cur.agent.runtime, self.worker_restarted)
        return envs, CurriculumDriver(self.scheduler, envs)

    def worker_restarted(self, event: dict[str, Any]) -> None:
        """A Ray worker died and was restarted with fresh envs (`runtime.vector: ray`): logged as
        an event, said on the console; the run goes on."""
        self.logger.event({"step": self.agent.global_step, **event})
        first, last = event["envs"]
        self.say(f"worker of envs {first}..{last} died ({event['error']}) during {event['during']}; "
                 f"restarted (restart {event['restart']}), its episodes truncated there")

    def run(self, until: int) -> None:
        agent, spec = self.agent, self.cur.spec
        every_ckpt, every_eval = spec.checkpoint.every_steps, spec.evaluation.every_steps
        next_ckpt = (agent.global_step // every_ckpt + 1) * every_ckpt
        next_eval = (agent.global_step // every_eval + 1) * every_eval
        previous_term = signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
        envs, driver = self.build_envs()
        # tqdm's own rate (steps/s since the start, in the bar) and the last update's (postfix)
        self.bar = tqdm(total=self.total, initial=agent.global_step, unit=" env steps", disable=not self.progress,
                        dynamic_ncols=True, file=sys.stderr)
        try:
            while agent.global_step < until:
                record = self.update(envs, driver)
                if agent.global_step >= next_eval:
                    next_eval += every_eval
                    rows = self.eval_rows()
                    results = self.evaluate(rows)
                    self.last_eval = (agent.global_step, rows, results)
                    record.update(_eval_metrics(results))
                    self.say(_eval_line(results))
                self.logger.log(agent.global_step, record)
                self.last_good = self.snapshot()
                if agent.global_step >= next_ckpt:
                    next_ckpt += every_ckpt
                    save_checkpoint(self.last_good, self.run_dir.checkpoint)
        except KeyboardInterrupt:
            # what is saved is the state after the last complete update; a rollout in progress
            # (at most one update's worth of steps) is said to be lost, not silently dropped
            save_checkpoint(self.last_good, self.run_dir.checkpoint)
            step = self.last_good["agent"]["global_step"]
            raise Interrupted(step, self.run_dir.path, discarded=self.collected) from None
        finally:
            self.bar.close()
            self.bar = None
            signal.signal(signal.SIGTERM, previous_term)
            self.logger.close()
            try:
                envs.close()
            except Exception:  # workers already gone after a Ctrl-C reached them too
                pass
        save_checkpoint(self.last_good, self.run_dir.checkpoint)
        if agent.global_step >= self.total:
            save_checkpoint({"config": self.config, "agent": self.last_good["agent"]}, self.run_dir.final)
            self.final_evaluation()

    def update(self, envs: VectorEnv, driver: CurriculumDriver) -> dict[str, Any]:
        """Collect one rollout, update once; the update's metrics record."""
        agent = self.agent
        agent.set_progress(agent.global_step / self.total)
        start_step, start_time = agent.global_step, time.perf_counter()
        bar, per_step = self.bar, envs.num_envs
        assert bar is not None
        self.collected = 0

        def on_step(*args) -> None:  # the bar moves while collecting, not once per update
            driver.on_step(*args)
            self.collected += per_step
            bar.update(per_step)

        agent.collect(envs, on_step)
        losses = agent.update()
        self.collected = 0
        sps = (agent.global_step - start_step) / (time.perf_counter() - start_time)
        episodes, events = driver.drain()
        for event in events:
            # on the run's clock, like the metrics: the scheduler counts only PPO's steps, so for a
            # warm-started run its own step would sit the expert's steps earlier on every plot
            self.logger.event({**asdict(event), "step": agent.global_step, "curriculum_step": event.step})
            why = ", step budget spent" if event.reason == "budget" else ""
            moved = f"{self.where(event.from_phase, event.from_stage)} -> {self.where(event.to_phase, event.to_stage)}"
            self.say(f"{event.kind}: {moved} (success {event.success_rate:.2f}{why})")
        window = self.scheduler.success_rates().get(f"{self.scheduler.phase}/{self.scheduler.stage}", 0.0)
        bar.set_postfix_str(f"stage {self.scheduler.stage}, success {window:.2f} over the window | "
                            f"last update {sps:,.0f} steps/s (collect + learn)")
        return {**self.position(), "steps_per_s": sps,
                **_episode_metrics(episodes), **{f"window_success/{k}": v for k, v in self.scheduler.success_rates().items()},
                **{f"sampling/{k}": v for k, v in self.scheduler.sampling_probabilities().items()},
                **losses}

    def position(self) -> dict[str, int | str]:
        """Where the curriculum stands, named in every metrics row."""
        return {"phase": self.scheduler.phase, "stage": self.scheduler.stage}

    def evaluation_row(self, when: str) -> dict[str, Any]:
        """A one-off evaluation (right after pretraining, from `init_from`), said on the console and
        returned as a metrics row that names the stage being trained as the periodic rows do, so a
        curve read per stage starts where the warm start or the loaded weights left it."""
        results = self.evaluate()
        self.say(_eval_line(results, when))
        return {**self.position(), **_eval_metrics(results)}

    def where(self, phase: int, stage: str) -> str:
        """A stage as the console names it: with several phases, which phase's task it belongs to
        (the xArm7 variants share their stage names, so `place -> place` would say nothing)."""
        return stage if len(self.cur.phases) == 1 else f"{self.cur.phases[phase].task.name}:{stage}"

    def eval_rows(self, final: bool = False) -> list[tuple[int, str, str | None]]:
        """What an evaluation plays, as (phase, stage, sub-task or None for the whole task): the
        current phase's task, or (`evaluation.tasks: all`) every phase and every sub-task of a set.
        The stage is `evaluation.stage`, else the current one in the current phase and the last
        one in the others; `final`: the last one everywhere."""
        ev = self.cur.spec.evaluation
        rows: list[tuple[int, str, str | None]] = []
        for p in range(len(self.cur.phases)) if ev.tasks == "all" else [self.scheduler.phase]:
            current = p == self.scheduler.phase and not final
            stage = ev.stage or (self.scheduler.stage if current else self.cur.phases[p].stages[-1])
            names = self.scheduler.task_names(p) if ev.tasks == "all" else []
            rows += [(p, stage, name) for name in (names if len(names) > 1 else [None])]
        return rows

    def evaluate(self, rows: list[tuple[int, str, str | None]] | None = None) -> list[StageResult]:
        """The curriculum's `evaluation` settings on `rows` (default `eval_rows()`), seeded apart
        from training."""
        ev = self.cur.spec.evaluation
        results = []
        for p, phase_rows in groupby(rows or self.eval_rows(), key=lambda row: row[0]):
            phase = self.cur.phases[p]
            results += evaluate_rows(self.agent, phase.task, phase.task_file, [row[1:] for row in phase_rows], ev.split,
                                     ev.episodes, seed=self.seed + 10_000, stop_on_success=ev.stop_on_success)
        return results

    def final_evaluation(self) -> None:
        """What the run ends with: the final policy on the final stage (`evaluation.stage`, else the
        phase's last) of what `evaluation.tasks` names, written to `final_eval.json` for
        `taskforge train` to print."""
        rows = self.eval_rows(final=True)
        if self.last_eval is not None and self.last_eval[0] == self.agent.global_step and self.last_eval[1] == rows:
            results = self.last_eval[2]  # the periodic evaluation already ran on this very policy
        else:
            results = self.evaluate(rows)
        save_json({"step": self.agent.global_step, **summarize(results)}, self.run_dir.final_eval)


def _eval_metrics(results: list[StageResult]) -> dict[str, float]:
    """An evaluation's metrics: the mean over its tasks and, with several, each task's own; for
    trials of K > 1 episodes (RL²) also the adaptation curve, `eval_episode/k` = success at
    episode k of a trial, so a run's log shows when its later episodes pull ahead of its first."""
    metrics = {"eval_success_rate": float(np.mean([r.success_rate for r in results])),
               "eval_return_mean": float(np.mean([r.mean_return for r in results]))}
    if len(results) > 1:
        metrics.update({f"eval/{r.task}": r.success_rate for r in results})
    if results[0].trial_episodes > 1:
        by_episode = np.concatenate([np.asarray(r.successes, dtype=float) for r in results]).mean(axis=0)
        metrics.update({f"eval_episode/{k + 1}": float(rate) for k, rate in enumerate(by_episode)})
    return metrics


def _eval_line(results: list[StageResult], when: str = "") -> str:
    """`eval place on test: success 0.94`; with several tasks the mean and the weakest one."""
    first, mean = results[0], float(np.mean([r.success_rate for r in results]))
    head = f"eval {', '.join(dict.fromkeys(r.stage for r in results))} on {first.split}{' ' + when if when else ''}"
    if len(results) == 1:
        line = f"{head}: success {mean:.2f}"
        if first.trial_episodes > 1 and first.successes:  # RL²: the ends of the adaptation curve
            ends = np.asarray(first.successes, dtype=float).mean(axis=0)
            line += f" (episode 1 {ends[0]:.2f} -> episode {first.trial_episodes} {ends[-1]:.2f})"
        return line
    worst = min(results, key=lambda r: r.success_rate)
    return f"{head}: mean success {mean:.2f} over {len(results)} tasks (lowest: {worst.task} {worst.success_rate:.2f})"


def _episode_metrics(episodes: EpisodeStats) -> dict[str, Any]:
    """The episodes finished during one update: means, per-stage success, and each reward term's
    per-episode sum (`episode_reward/<term>`, what a user tunes a stage's weights with)."""
    def mean(values: list) -> float | None:
        return float(np.mean(values)) if values else None

    per_stage: dict[str, list[bool]] = {}
    for success, stage in zip(episodes.successes, episodes.stages):
        per_stage.setdefault(stage, []).append(success)
    return {
        "episodes": len(episodes.returns),
        "unstable_episodes": episodes.unstable,
        "return_mean": mean(episodes.returns),
        "length_mean": mean(episodes.lengths),
        "success_rate": mean(episodes.successes),
        # RL²: success_rate is the trials' last episode (after adapting); this their first
        "success_first_episode": mean(episodes.first_successes),
        **{f"success/{stage}": float(np.mean(v)) for stage, v in per_stage.items()},
        **{f"episode_reward/{term}": float(np.mean(v)) for term, v in episodes.reward_terms.items()},
    }


def _raise_keyboard_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt
