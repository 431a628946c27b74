"""`taskforge train`: PPO along a curriculum, with logs, atomic checkpoints and resume.

Reading order: load and check everything (no file is written before the inputs are known to be
good) -> set up the run directory -> build agent, scheduler and envs -> the loop (collect,
update, log, maybe rebuild envs for a new phase, maybe evaluate, maybe checkpoint) -> final save.
"""

from __future__ import annotations

import copy
import signal
import sys
import time
from dataclasses import asdict
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector import VectorEnv
from tqdm import tqdm

from taskforge.agents import PPOAgent, agent_observation_space, make_vector_env, set_torch_threads, wrap_for_training
from taskforge.curriculum import CurriculumScheduler
from taskforge.envs import ResolvedCurriculum, TaskEnv, load_curriculum, probe_phases
from taskforge.evaluation import evaluate
from taskforge.spec import AgentSpec, SpecError, TaskSpec
from taskforge.training.checkpoint import load_checkpoint, save_checkpoint, save_json
from taskforge.training.driver import CurriculumDriver
from taskforge.training.metrics import MetricsLogger
from taskforge.training.warm_start import prepare_warm_start

CHECKPOINT = "checkpoint.pt"
FINAL = "final.pt"
FINAL_EVAL = "final_eval.json"


class Interrupted(Exception):
    """Training stopped by Ctrl-C or SIGTERM after saving a checkpoint."""

    def __init__(self, step: int, run_dir: Path):
        super().__init__(f"interrupted at step {step:,}; checkpoint saved in {run_dir} (continue with --resume)")
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


def _train_env(task: TaskSpec, task_file: str, privileged: bool, agent: AgentSpec) -> gymnasium.Env:
    """One worker's env: a `TaskEnv` on the train goals, in trials for RL²."""
    return wrap_for_training(TaskEnv(task, task_file, split="train", privileged=privileged), agent)


def _build_envs(cur: ResolvedCurriculum, phase: int, privileged: bool) -> VectorEnv:
    spec = cur.agent
    p = cur.phases[phase]
    fns = [partial(_train_env, p.task, str(p.task_file), privileged, spec) for _ in range(spec.ppo.num_envs)]
    return make_vector_env(fns, spec.runtime)


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
    (each chunk would anneal the learning rate to zero)."""
    cur = load_curriculum(curriculum_file)
    for warning in cur.warnings:
        print(f"warning: {warning}", file=sys.stderr)
    run_dir = Path(run_dir) if run_dir else Path("runs") / f"{cur.spec.name}-seed{cur.spec.seed if seed is None else seed}"
    ckpt_file = run_dir / CHECKPOINT
    state: dict[str, Any] | None = None
    if resume:
        if not ckpt_file.is_file():
            raise SpecError.single(run_dir, "", f"no {CHECKPOINT} to resume from; start without --resume")
        state = load_checkpoint(ckpt_file)
        stored = state["config"]
        if stored["curriculum"] != cur.spec.model_dump(mode="json") or stored["agent"] != cur.agent.model_dump(mode="json"):
            raise SpecError.single(
                curriculum_file, "", f"differs from the curriculum/agent of the run in {run_dir} (see its config.json); "
                "resume with the same files or start a new --run-dir",
            )
        if seed is not None and seed != stored["seed"]:
            raise SpecError.single(run_dir, "", f"was started with --seed {stored['seed']}; resume without --seed or with the same one")
        seed = stored["seed"]
    elif ckpt_file.exists():
        raise SpecError.single(run_dir, "", f"already holds a run ({CHECKPOINT}); pass --resume to continue it or choose another --run-dir")
    seed = cur.spec.seed if seed is None else seed
    total = steps or (state["config"]["total_steps"] if state else cur.spec.total_steps)
    until = total if stop_at is None else min(total, stop_at)
    config = run_config(cur, seed, total)

    agent_spec = cur.agent
    privileged = agent_spec.asymmetric_critic
    set_torch_threads(agent_spec.runtime)
    shapes = probe_phases([(p.task, p.task_file) for p in cur.phases], privileged, cur.file)
    if privileged and shapes.privileged_size == 0:
        raise SpecError.single(cur.agent_file, "asymmetric_critic", "the curriculum's backends expose no privileged features; set it to false")
    obs_space = agent_observation_space(agent_spec, shapes.observation_space, shapes.action_space)
    agent = PPOAgent(agent_spec, obs_space, shapes.action_space, shapes.privileged_size, seed)
    scheduler = CurriculumScheduler(cur.spec, [p.stages for p in cur.phases], shapes.task_names, seed)
    if state:
        agent.load_state_dict(state["agent"])
        scheduler.load_state_dict(state["curriculum"])
    # demos: behaviour-cloning pretraining (fresh runs only) and PPO's decaying BC term
    warm = prepare_warm_start(cur, agent, run_dir, seed, resumed=state is not None, progress=progress)

    run_dir.mkdir(parents=True, exist_ok=True)
    for stale in run_dir.glob(".*.tmp"):  # half-written by a process killed mid-save
        stale.unlink()
    save_json(config, run_dir / "config.json")
    logger = MetricsLogger(run_dir, resume_step=agent.global_step if state else None)
    if warm is not None:
        if warm.metrics is not None:  # evaluate right after pretraining: the curve starts where the demos left it
            result = _evaluate_current(agent, cur, scheduler, seed)
            warm.metrics.update({"eval_success_rate": result.success_rate, "eval_return_mean": result.mean_return})
            if progress:
                print(f"[{agent.global_step:,}] eval {result.stage} on {result.split} after pretraining: "
                      f"success {result.success_rate:.2f}", file=sys.stderr)
        warm.record(run_dir, logger)

    def snapshot() -> dict[str, Any]:
        return copy.deepcopy({"config": config, "agent": agent.state_dict(), "curriculum": scheduler.state_dict()})

    every_ckpt = cur.spec.checkpoint.every_steps
    every_eval = cur.spec.evaluation.every_steps
    next_ckpt = (agent.global_step // every_ckpt + 1) * every_ckpt
    next_eval = (agent.global_step // every_eval + 1) * every_eval
    last_good = snapshot()  # what a Ctrl-C saves: the state after the last complete update
    last_eval: tuple[int, Any] | None = None

    previous_term = signal.signal(signal.SIGTERM, _raise_keyboard_interrupt)
    envs = _build_envs(cur, scheduler.phase, privileged)
    driver = CurriculumDriver(scheduler, envs, scheduler.phase, cur.phases[scheduler.phase].stages[-1])
    bar = tqdm(total=total, initial=agent.global_step, unit="step", disable=not progress, dynamic_ncols=True, file=sys.stderr)
    try:
        while agent.global_step < until:
            agent.set_progress(agent.global_step / total)
            start_step, start_time = agent.global_step, time.perf_counter()
            agent.collect(envs, driver.on_step)
            losses = agent.update()
            sps = (agent.global_step - start_step) / (time.perf_counter() - start_time)
            episodes, events = driver.drain()
            for event in events:
                logger.event(asdict(event))
                why = ", step budget spent" if event.reason == "budget" else ""
                bar.write(f"[{agent.global_step:,}] {event.kind}: {event.from_stage} -> {event.to_stage} (success {event.success_rate:.2f}{why})")

            per_stage: dict[str, list[bool]] = {}
            for success, stage in zip(episodes.successes, episodes.stages):
                per_stage.setdefault(stage, []).append(success)
            record: dict[str, Any] = {
                "phase": scheduler.phase,
                "stage": scheduler.stage,
                "steps_per_s": sps,
                "episodes": len(episodes.returns),
                "return_mean": float(np.mean(episodes.returns)) if episodes.returns else None,
                "length_mean": float(np.mean(episodes.lengths)) if episodes.lengths else None,
                "success_rate": float(np.mean(episodes.successes)) if episodes.successes else None,
                # RL²: success_rate is the trials' last episode (after adapting); this their first
                "success_first_episode": float(np.mean(episodes.first_successes)) if episodes.first_successes else None,
                **{f"success/{stage}": float(np.mean(v)) for stage, v in per_stage.items()},
                **{f"window_success/{k}": v for k, v in scheduler.success_rates().items()},
                **losses,
            }
            if agent.global_step >= next_eval:
                next_eval += every_eval
                result = _evaluate_current(agent, cur, scheduler, seed)
                last_eval = (agent.global_step, result)
                record.update({"eval_success_rate": result.success_rate, "eval_return_mean": result.mean_return})
                bar.write(f"[{agent.global_step:,}] eval {result.stage} on {result.split}: success {result.success_rate:.2f}")
            logger.log(agent.global_step, record)
            bar.update(agent.global_step - start_step)
            window = scheduler.success_rates().get(f"{scheduler.phase}/{scheduler.stage}", 0.0)
            bar.set_postfix_str(f"{scheduler.stage} success {window:.2f} | {sps:,.0f} steps/s")

            if scheduler.phase != driver.phase:  # a new task file: new envs, same agent
                envs.close()
                envs = _build_envs(cur, scheduler.phase, privileged)
                driver = CurriculumDriver(scheduler, envs, scheduler.phase, cur.phases[scheduler.phase].stages[-1])
                agent.reset_envs()
            last_good = snapshot()
            if agent.global_step >= next_ckpt:
                next_ckpt += every_ckpt
                save_checkpoint(last_good, ckpt_file)
    except KeyboardInterrupt:
        save_checkpoint(last_good, ckpt_file)
        raise Interrupted(last_good["agent"]["global_step"], run_dir) from None
    finally:
        bar.close()
        signal.signal(signal.SIGTERM, previous_term)
        logger.close()
        try:
            envs.close()
        except Exception:  # workers already gone after a Ctrl-C reached them too
            pass
    save_checkpoint(last_good, ckpt_file)
    if agent.global_step >= total:
        save_checkpoint({"config": config, "agent": last_good["agent"]}, run_dir / FINAL)
        _final_evaluation(agent, cur, scheduler, seed, run_dir, last_eval)
    return run_dir


def _final_evaluation(agent: PPOAgent, cur: ResolvedCurriculum, scheduler: CurriculumScheduler, seed: int,
                      run_dir: Path, last_eval: tuple[int, Any] | None) -> None:
    """What the run ends with: the evaluation (the curriculum's `evaluation` settings) of the final
    policy on the final stage (`evaluation.stage`, else the phase's last), written to
    `final_eval.json` for `taskforge train` to print."""
    phase = cur.phases[scheduler.phase]
    stage = cur.spec.evaluation.stage or phase.stages[-1]
    if last_eval is not None and last_eval[0] == agent.global_step and last_eval[1].stage == stage:
        result = last_eval[1]  # the periodic evaluation already ran on this very policy
    else:
        result = _evaluate_stage(agent, cur, scheduler.phase, stage, seed)
    save_json({"step": agent.global_step, **result.as_dict()}, run_dir / FINAL_EVAL)


def _evaluate_current(agent: PPOAgent, cur: ResolvedCurriculum, scheduler: CurriculumScheduler, seed: int):
    return _evaluate_stage(agent, cur, scheduler.phase, cur.spec.evaluation.stage or scheduler.stage, seed)


def _evaluate_stage(agent: PPOAgent, cur: ResolvedCurriculum, phase_index: int, stage: str, seed: int):
    """The curriculum's `evaluation` settings on one stage of a phase; seeded apart from training."""
    phase, ev = cur.phases[phase_index], cur.spec.evaluation
    return evaluate(agent, phase.task, phase.task_file, stage, ev.split, ev.episodes, seed=seed + 10_000, stop_on_success=ev.stop_on_success)


def _raise_keyboard_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt
