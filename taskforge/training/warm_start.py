"""The curriculum's `warm_start`: learn from the scripted expert before PPO, then hand over to
PPO without losing what was learnt.

Reading order (fresh runs; `--resume` only reinstalls the BC term from the saved data):

1. demonstrations: a file, or scripted episodes recorded now (train goals);
2. behaviour cloning of the actor and value regression of the critic on them (`agents/bc.py`);
3. DAgger rounds (`dagger.py`): the student's own states, labelled by the expert, aggregated;
4. the hand-over to PPO (`fine_tune`): exploration noise sized from the student's cloning error
   instead of the preset's std of 1, critic-only updates first, and DAPG's decaying BC term on
   everything the expert labelled.

Every env step the expert or the student took here counts in the run's step budget, so a curve
of a warm-started run is comparable with one from scratch at the same x.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from taskforge import demos as demo_io
from taskforge.agents import MPCAgent, PPOAgent, make_vector_env
from taskforge.agents.bc import fit_exploration_std, pretrain, returns_to_go, scaled_rewards
from taskforge.atomic import atomic_write
from taskforge.demos.labels import ExpertLabels
from taskforge.envs import ResolvedCurriculum, TaskEnv
from taskforge.run import RunDir
from taskforge.spec import SpecError
from taskforge.spec.curriculum import WarmStartSpec
from taskforge.training.dagger import DaggerRound, Labelled, dagger


@dataclass
class WarmStart:
    demos: demo_io.Demos
    generated: bool
    metrics: dict[str, Any] | None
    """Pretraining metrics (None when resuming: the checkpoint already holds the result)."""
    labelled: Labelled | None = None
    """DAgger's aggregate beyond the demos, kept for `--resume`."""

    def record(self, run: RunDir, logger) -> None:
        """After the run directory exists: keep generated demos and DAgger's labels for
        `--resume`, and log the pretraining."""
        if self.generated and (self.metrics is not None or not run.demos.exists()):
            demo_io.save(self.demos, run.demos)
        if self.labelled is not None and (self.metrics is not None or not run.dagger.exists()):
            obs, act, starts = self.labelled.fields()
            atomic_write(run.dagger, lambda f: np.savez_compressed(f, observations=obs, actions=act, episode_starts=starts))
        if self.metrics is not None:
            logger.log(int(self.metrics["expert_steps"]), self.metrics)


def prepare_warm_start(
    cur: ResolvedCurriculum, agent: PPOAgent | MPCAgent, run: RunDir, seed: int, resumed: bool, progress: bool
) -> WarmStart | None:
    """Load or generate the demos and apply them to `agent` (see the module doc); writes no file.
    Bad demos (wrong stage or observation size, no successful episode) are a `SpecError` at
    `warm_start.*`."""
    ws = cur.spec.warm_start
    if ws is None:
        return None
    if isinstance(agent, MPCAgent):
        return _seed_model(cur, ws, agent, run, seed, resumed, progress)
    demos, generated = _demonstrations(cur, ws, run, seed, resumed, progress)
    _check_size(cur, demos, agent.obs_normalizer.rms.mean.shape[0])

    if resumed:  # the checkpoint holds the pretrained networks; only the BC term is not saved in it
        labelled = _load_labelled(run.dagger)
        aggregate = _as_labelled(demos) if labelled is None else _as_labelled(demos).extend(labelled)
        _set_regularizer(agent, ws, aggregate)
        return WarmStart(demos, generated, None, labelled)

    # 2. behaviour cloning (actor) and value regression (critic) on the demos
    _say(progress, f"warm start: behaviour cloning on {demos.num_steps:,} steps of {demos.num_episodes} demos ({ws.bc_epochs} epochs)")
    rewards = scaled_rewards(agent, demos.rewards, demos.episode_starts, demos.terminated)
    targets = returns_to_go(rewards, demos.episode_starts, demos.truncated, agent.spec.ppo.gamma)
    metrics = pretrain(
        agent, demos.observations, demos.actions, targets, epochs=ws.bc_epochs, batch_size=ws.bc_batch_size,
        learning_rate=ws.bc_learning_rate, privileged=demos.privileged, progress=progress,
        episode_starts=demos.episode_starts,
    )
    metrics["bc_demo_episodes"] = float(demos.num_episodes)
    metrics.update({f"demo_success/{name}": rate for name, rate in demos.metadata.get("success_by_task", {}).items()})
    aggregate = _as_labelled(demos)
    _set_exploration(agent, ws, aggregate)

    # 3. DAgger: the student's own states, labelled by the expert
    expert_steps = int(demos.metadata.get("steps_run", demos.num_steps))
    labelled = None
    if ws.dagger.rounds > 0:
        recorded = demos.metadata.get("stage") if len(cur.warm_start_phases()) == 1 else None  # a demos file names its stage
        aggregate = _run_dagger(cur, ws, agent, aggregate, recorded, seed, progress, metrics)
        labelled = aggregate.after(demos.num_steps)
        expert_steps += len(labelled)  # the last refit already sized the std on the whole aggregate
        metrics["dagger_samples"] = float(len(labelled))

    # 4. the hand-over to PPO
    ppo = agent.spec.ppo
    if ws.fine_tune.critic_warmup_steps:
        _say(progress, f"warm start: the first {ws.fine_tune.critic_warmup_steps:,} PPO steps train the critic only")
    agent.warm_up_critic(math.ceil(ws.fine_tune.critic_warmup_steps / (ppo.num_envs * ppo.rollout_steps)))
    if ws.fine_tune.freeze_observation_statistics:
        agent.freeze_observation_statistics()
    _set_regularizer(agent, ws, aggregate)
    agent.global_step += expert_steps  # the expert's and the student's steps count in the budget
    metrics["expert_steps"] = float(expert_steps)
    std = agent.policy.actor_logstd.detach().exp().numpy()
    metrics.update({f"exploration_std/{i}": float(s) for i, s in enumerate(std)})
    return WarmStart(demos, generated, metrics, labelled)


def _seed_model(
    cur: ResolvedCurriculum, ws: WarmStartSpec, agent: MPCAgent, run: RunDir, seed: int, resumed: bool, progress: bool
) -> WarmStart:
    """`algo: mpc`'s warm start: the demos' transitions seed the model's data and it is fitted
    on them before the first plan (the planner starts from a model that has seen the task
    solved); with `mpc.prior_trajectories` they are cloned into the planner's prior too. A resumed
    run's buffer and prior are in its checkpoint."""
    demos, generated = _demonstrations(cur, ws, run, seed, resumed, progress)
    _check_size(cur, demos, agent.observation_space.shape[0])
    if resumed:
        return WarmStart(demos, generated, None)
    stage = _demo_stage(ws, demos.metadata.get("stage"), cur.warm_start_phases()[0])
    if ", " in stage:  # `phase: all` over phases whose last stages differ
        raise SpecError.single(cur.file, "warm_start.stage", f"one stage for algo mpc's demos (their rewards are that stage's), not several ({stage})")
    added = agent.add_demonstrations(demos.observations, demos.actions, demos.rewards, demos.episode_starts, stage)
    _say(progress, f"warm start: the model is fitted on {added:,} transitions of {demos.num_episodes} demos")
    metrics = {f"demo_{k}": v for k, v in agent.update().items()}
    if agent.prior is not None:
        _say(progress, f"warm start: the planner's prior is cloned from them ({ws.bc_epochs} epochs)")
        fit = agent.fit_prior(demos.observations, demos.actions, ws.bc_epochs, ws.bc_batch_size, ws.bc_learning_rate)
        metrics |= {f"demo_{k}": v for k, v in fit.items()}
    expert_steps = int(demos.metadata.get("steps_run", demos.num_steps))
    agent.global_step += expert_steps  # the expert's steps count in the budget
    metrics.update(expert_steps=float(expert_steps), demo_transitions=float(added), bc_demo_episodes=float(demos.num_episodes))
    return WarmStart(demos, generated, metrics)


def load_demos_file(cur: ResolvedCurriculum, obs_size: int | None = None) -> demo_io.Demos:
    """The curriculum's `warm_start.demos` file, checked as training will use it: readable, of
    the warm start's stage and (given `obs_size`, the policy's input) of the right observation
    size. `validate` calls this too, so a file `train` would refuse is not reported `ok`."""
    ws = cur.spec.warm_start
    assert ws is not None and ws.demos is not None and cur.demos_file is not None
    try:
        demos = demo_io.load(cur.demos_file)
    except SpecError as exc:
        raise SpecError.single(cur.file, "warm_start.demos", "; ".join(str(i) for i in exc.issues)) from None
    recorded = demos.metadata.get("stage")
    if ws.stage is not None and recorded != ws.stage:
        raise SpecError.single(cur.file, "warm_start.stage", f"'{ws.stage}', but {cur.demos_file} holds demos of stage '{recorded}'")
    if obs_size is not None:
        _check_size(cur, demos, obs_size)
    return demos


def _check_size(cur: ResolvedCurriculum, demos: demo_io.Demos, size: int) -> None:
    if demos.observations.shape[1] != size:
        where = "warm_start.demos" if cur.spec.warm_start and cur.spec.warm_start.demos else "warm_start.phase"
        raise SpecError.single(cur.file, where, f"demo observations have {demos.observations.shape[1]} floats; the policy reads {size}")


def _demonstrations(
    cur: ResolvedCurriculum, ws: WarmStartSpec, run: RunDir, seed: int, resumed: bool, progress: bool
) -> tuple[demo_io.Demos, bool]:
    """The demos file, the demos a resumed run saved, or newly recorded scripted episodes."""
    saved = run.demos
    if ws.demos is not None:
        return load_demos_file(cur), False
    if resumed and saved.is_file():
        return demo_io.load(saved), True
    phases, total = cur.warm_start_phases(), ws.generate_episodes
    assert total is not None  # the spec requires demos or generate_episodes
    parts = []
    for i, phase in enumerate(phases):  # `phase: all`: the episodes split evenly over the phases
        episodes = total // len(phases) + (i < total % len(phases))
        stage = ws.stage or phase.stages[-1]
        _say(progress, f"warm start: recording {episodes} scripted episodes of {phase.task.name}:{stage}")
        part = demo_io.generate(phase.task_file, stage, max(episodes, 1), seed=seed, split="train", progress=progress)
        if part.num_steps == 0:
            raise SpecError.single(
                cur.file, "warm_start.generate_episodes",
                f"no scripted episode of {phase.task.name}:{stage} succeeded out of {episodes}; no demos to learn from",
            )
        parts.append(part)
    demos = demo_io.concatenate(parts)
    # a result, not progress: printed with --no-progress too (and logged as demo_success/<task>)
    print("warm start: scripted success on the train goals: " + _success_by_task(demos.metadata), file=sys.stderr)
    return demos, True


def _success_by_task(metadata: dict[str, Any]) -> str:
    """The expert's success per task, weak ones (below 0.8) named: a weak teacher caps its student,
    so a user sees which task it is before blaming the learner."""
    rates = metadata.get("success_by_task", {})
    weak = [name for name, rate in rates.items() if rate < 0.8]
    line = ", ".join(f"{name} {rate:.2f}" for name, rate in rates.items())
    return line + (f" (weak teacher: {', '.join(weak)})" if weak else "")


def _say(progress: bool, line: str) -> None:
    """A start-up phase on stderr, so minutes of warm start are not minutes of silence."""
    if progress:
        print(line, file=sys.stderr, flush=True)


def _as_labelled(demos: demo_io.Demos) -> Labelled:
    return Labelled(demos.observations, demos.actions, demos.episode_starts)


def _set_regularizer(agent: PPOAgent, ws: WarmStartSpec, data: Labelled) -> None:
    """DAPG's decaying BC term on everything the expert labelled (`warm_start.regularizer`)."""
    if ws.regularizer.weight > 0:
        agent.set_demo_regularizer(data.observations, data.actions, ws.regularizer.weight, ws.regularizer.decay,
                                   episode_starts=data.episode_starts)


def _set_exploration(agent: PPOAgent, ws: WarmStartSpec, data: Labelled) -> None:
    """Set PPO's starting std (`fine_tune.exploration_std`) from the student on these data."""
    ft = ws.fine_tune
    if ft.exploration_std == "auto":
        fit_exploration_std(agent, data.observations, data.actions, ft.std_scale, ft.std_min, ft.std_max, data.episode_starts)
    elif ft.exploration_std != "preset":
        agent.policy.actor_logstd.data.fill_(math.log(float(ft.exploration_std)))


def _demo_stage(ws: WarmStartSpec, recorded: str | None, phase) -> str:
    """The stage the demos are of: the warm start's `stage`, else the one a demos file was
    recorded on, else the phase's last."""
    return ws.stage or recorded or phase.stages[-1]


def _labelled_env(phase, stage: str, privileged: bool) -> ExpertLabels:
    """One DAgger worker env: the warm-start stage on the train goals, labelled by the expert."""
    return ExpertLabels(TaskEnv(phase.task, phase.task_file, stage=stage, split="train", privileged=privileged), stage)


def _run_dagger(
    cur: ResolvedCurriculum, ws: WarmStartSpec, agent: PPOAgent, demos: Labelled, recorded: str | None, seed: int,
    progress: bool, metrics: dict[str, float],
) -> Labelled:
    """DAgger's rounds; each round's student success (overall and per sub-task) goes into `metrics`."""
    phases = cur.warm_start_phases()
    fns = [  # env i plays phase i mod the number of phases
        partial(_labelled_env, phase, _demo_stage(ws, recorded, phase), agent.privileged_dim > 0)
        for phase in (phases[i % len(phases)] for i in range(agent.spec.ppo.num_envs))
    ]
    envs = make_vector_env(fns, agent.spec.runtime)

    def refit(data: Labelled) -> dict[str, float]:
        fit = pretrain(
            agent, data.observations, data.actions, epochs=ws.dagger.epochs, batch_size=ws.bc_batch_size,
            learning_rate=ws.bc_learning_rate, update_normalizer=False, progress=progress,
            episode_starts=data.episode_starts,
        )
        _set_exploration(agent, ws, data)  # the next round explores as PPO will
        return fit

    def report(k: int, batch: DaggerRound, refit_metrics: dict[str, float]) -> None:
        by_task = batch.success_by_task()
        if batch.success_rate is not None:
            metrics[f"dagger_student_success/round{k}"] = batch.success_rate
        if len(by_task) > 1:
            metrics.update({f"dagger_student_success/round{k}/{name}": rate for name, rate in by_task.items()})
        if progress:
            rate = "-" if batch.success_rate is None else f"{batch.success_rate:.2f}"
            tasks = f" ({', '.join(f'{n} {r:.2f}' for n, r in sorted(by_task.items()))})" if len(by_task) > 1 else ""
            print(
                f"DAgger round {k}/{ws.dagger.rounds}: student success {rate} over {len(batch.episode_successes)} episodes{tasks}, "
                f"{len(batch.observations):,} states labelled, action MSE after refit {refit_metrics['bc_action_mse']:.4f}",
                file=sys.stderr,
            )

    try:
        return dagger(agent, envs, demos, ws.dagger.rounds, ws.dagger.steps_per_round, refit, seed, report)
    finally:
        envs.close()


def _load_labelled(path: Path) -> Labelled | None:
    """DAgger's labels saved by an earlier call. Files from before recurrent warm starts have no
    `episode_starts`: every step its own row, as an MLP reads them."""
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as data:
        starts = data["episode_starts"] if "episode_starts" in data else np.ones(len(data["actions"]), dtype=bool)
        return Labelled(data["observations"], data["actions"], starts)
