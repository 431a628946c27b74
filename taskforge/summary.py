"""Human-readable summaries of validated files (what `taskforge validate` and `tasks` print)."""

from __future__ import annotations

from taskforge.envs import ResolvedCurriculum
from taskforge.spec import SEED_PLACEHOLDER, AgentSpec, ConditionSpec, TaskSpec
from taskforge.spec.curriculum import PromotionSpec


def condition_text(c: ConditionSpec) -> str:
    parts = []
    if c.above is not None:
        parts.append(f"{c.feature} > {c.above:g}")
    if c.below is not None:
        parts.append(f"{c.feature} < {c.below:g}")
    return " and ".join(parts)


def _interval(name: str, bounds: tuple[float, float]) -> str:
    return f"{name} {bounds[0]:g}..{bounds[1]:g}"


def _regions(backend) -> list[str]:
    """Where objects start and goals lie, for backends whose task file sets them (xArm7);
    Meta-World's come from the env itself."""
    lines = []
    for label, field, axes in (("object starts", "object_region", "xy"), ("goals", "goal_region", "xyz")):
        region = getattr(backend, field, None)
        if region is not None:
            where = ", ".join(_interval(a, getattr(region, a)) for a in axes)
            lines.append(f"  {label}: {where} m" + (" (z above the table top)" if "z" in axes else ""))
    return lines


def task_summary(task: TaskSpec) -> list[str]:
    b = task.backend
    source = b.describe()
    goals = "reset seeds" if b.type == "gymnasium" else f"goals {'observable' if task.goals.observable else 'hidden'}, seed {task.goals.seed},"
    lines = [
        f"task {task.name}: backend {b.type}, {source}, episodes of {task.max_episode_steps} steps",
        f"  {goals} train {'fresh each task' if task.goals.train.draw == 'fresh' else task.goals.train.count}, "
        f"test (held out) {task.goals.test.count}",
        *_regions(b),
        f"  stages ({len(task.stages)}):",
    ]
    for i, stage in enumerate(task.stages):
        terms = ", ".join(f"{r.weight:+g}*{r.term}" for r in stage.rewards)
        extras = []
        if stage.max_episode_steps:
            extras.append(f"{stage.max_episode_steps} steps")
        if stage.goal.height != "keep" or stage.goal.distance_scale != 1.0:
            spread = f" (height x{stage.goal.height_scale:g})" if stage.goal.height_scale else ""
            extras.append(f"goal height={stage.goal.height}{spread}, distance x{stage.goal.distance_scale:g}")
        if stage.terminate_on_success:
            extras.append("ends on success")
        tail = f" [{'; '.join(extras)}]" if extras else ""
        lines.append(f"    {i + 1}. {stage.name}{tail}")
        lines.append(f"       reward  = {terms}")
        lines.append(f"       success = {' and '.join(condition_text(c) for c in stage.success.all)}")
    rand = task.randomization
    if rand.physics:
        lines.append("  physics randomisation:")
        for p in rand.physics:
            names = f" on {', '.join(p.names)}" if p.names else ""
            lines.append(f"    {p.target}: {p.op} by {p.describe()}{names}{'' if p.per_element else ' (shared draw)'}")
    for label, noise in (("observation noise", rand.observation_noise), ("action noise", rand.action_noise)):
        parts = [f"{k} {d.describe()}" for k, d in (("per step", noise.per_step), ("per episode", noise.per_episode)) if d]
        if parts:
            lines.append(f"  {label}: {', '.join(parts)}")
    lat = rand.action_latency
    if lat.max_steps:
        lines.append(f"  action latency: {lat.min_steps}..{lat.max_steps} steps")
    if rand.action_backlash is not None:
        lines.append(f"  action backlash width: {rand.action_backlash.describe()}")
    if rand.object_start == "random":
        lines.append("  object start: random per task instance, independent of the goal")
    return lines


def agent_summary(agent: AgentSpec) -> list[str]:
    p, ppo = agent.policy, agent.ppo
    # the layers in the order the input meets them: encoder, core, MLP
    shape = f"mlp {p.hidden_sizes}" if p.type == "mlp" else " -> ".join(
        ([str(p.encoder_sizes)] if p.encoder_sizes else []) + [f"{p.type} {p.recurrent_size}"] + ([str(p.hidden_sizes)] if p.hidden_sizes else [])
    )
    scale = agent.rl2.reward_input_scale if agent.rl2 else 1.0
    return [
        f"agent {agent.name}: {agent.algo}, policy {shape} ({p.activation}), "
        f"actions {p.action_bounds}{', asymmetric critic' if agent.asymmetric_critic else ''}",
        f"  {ppo.num_envs} envs x {ppo.rollout_steps} steps per update, {ppo.update_epochs} epochs x "
        f"{ppo.num_minibatches} minibatches, lr {ppo.learning_rate:g}, gamma {ppo.gamma:g}, lambda {ppo.gae_lambda:g}"
        + (f", BPTT {ppo.bptt_length} steps" if p.type != "mlp" and ppo.bptt_length else ""),
    ] + ([f"  RL² trials of {agent.trial_episodes} episodes per goal; input obs + previous action, "
          f"reward{f' x {scale:g}' if scale != 1.0 else ''}, episode start"]
         if agent.algo == "rl2" else [])


def _promotion(rule: PromotionSpec) -> str:
    """A promotion rule in words: the curriculum's, and a phase's own, which replaces it whole."""
    return (
        f"promote at success >= {rule.threshold:g} over {rule.window} episodes (min {rule.min_steps:,} steps"
        + (f", or after {rule.max_steps:,} steps in a stage" if rule.max_steps else "")
        + ")"
    )


def curriculum_summary(cur: ResolvedCurriculum) -> list[str]:
    spec = cur.spec
    lines = [
        f"curriculum {spec.name}: {spec.total_steps:,} steps, seed {spec.seed}, agent {cur.agent.name} ({cur.agent_file})",
        f"  {_promotion(spec.promotion)}; replay {spec.replay.fraction:g}; "
        f"demotion {'on' if spec.demotion.enabled else 'off'}; sub-task sampling {spec.sampling.mode}",
    ]
    for i, (phase, phase_spec) in enumerate(zip(cur.phases, spec.phases)):
        own_rule = f"; this phase: {_promotion(phase_spec.promotion)}" if phase_spec.promotion else ""
        lines.append(f"  phase {i + 1}: {phase.task.name} ({phase.task_file}): {' -> '.join(phase.stages)}{own_rule}")
    lines.append(
        f"  evaluate every {spec.evaluation.every_steps:,} steps on {spec.evaluation.episodes} "
        f"{spec.evaluation.split} {'trials' if cur.agent.algo == 'rl2' else 'episodes'}"
        f"{' of every task of every phase' if spec.evaluation.tasks == 'all' else ''}; checkpoint every {spec.checkpoint.every_steps:,} steps"
    )
    if cur.init_from is not None:
        learnt = "model and data" if cur.agent.algo == "mpc" else "networks and normaliser statistics"
        per_seed = f" ({SEED_PLACEHOLDER}: the run's seed)" if SEED_PLACEHOLDER in (cur.spec.init_from or "") else ""
        lines.append(f"  start from the {learnt} of {cur.init_from}{per_seed} (optimizer, steps and curriculum fresh)")
    ws = spec.warm_start
    if ws is not None:
        tasks = " + ".join(f"{p.task.name}:{ws.stage or p.stages[-1]}" for p in cur.warm_start_phases())
        source = str(cur.demos_file) if ws.demos else f"{ws.generate_episodes} scripted episodes of {tasks}"
        if cur.agent.algo == "mpc":  # the demos are the model's first data (and, with a prior, a cloned policy)
            prior = cur.agent.planning.prior_trajectories
            start = " and the search starts from it" if cur.agent.planning.search_from_prior else ""
            cloned = f"; a policy cloned from them ({ws.bc_epochs} epochs) proposes {prior} of each planning round's candidates{start}" if prior else ""
            if prior and cur.agent.planning.value_policy:
                cloned += " (the terminal value's policy, fitted on by TD3+BC from then on)"
            lines.append(f"  warm start from {source}: they seed the dynamics model's data, fitted on them before the first plan{cloned}")
        else:
            ft = ws.fine_tune
            std = ft.exploration_std if isinstance(ft.exploration_std, str) else f"{ft.exploration_std:g}"
            lines.append(
                f"  warm start from {source}: BC {ws.bc_epochs} epochs"
                + (f", {ws.dagger.rounds} DAgger rounds of {ws.dagger.steps_per_round:,} steps" if ws.dagger.rounds else "")
                + f"; PPO std {std}, {ft.critic_warmup_steps:,} critic-only steps, "
                f"observation statistics {'frozen' if ft.freeze_observation_statistics else 'updating'}, "
                f"BC term {ws.regularizer.weight:g} x {ws.regularizer.decay:g}^update"
            )
    return lines
