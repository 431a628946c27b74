"""The curriculum's `warm_start`: get the demonstrations (a file, or scripted episodes recorded
now), pretrain the agent on them (fresh runs only), and install PPO's decaying BC term.

Generated demos are saved in the run directory (`demos.npz`), so `--resume` reinstalls the
same regulariser without recording them again.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from taskforge import demos as demo_io
from taskforge.agents import PPOAgent
from taskforge.agents.bc import pretrain, returns_to_go, scaled_rewards
from taskforge.envs import ResolvedCurriculum
from taskforge.spec import SpecError

DEMOS_FILE = "demos.npz"


@dataclass
class WarmStart:
    demos: demo_io.Demos
    generated: bool
    metrics: dict[str, Any] | None
    """Pretraining metrics (None when resuming: the checkpoint already holds the result)."""

    def record(self, run_dir: Path, logger) -> None:
        """After the run directory exists: keep generated demos for `--resume`, and log the
        pretraining at step 0."""
        if self.generated and not (run_dir / DEMOS_FILE).exists():
            demo_io.save(self.demos, run_dir / DEMOS_FILE)
        if self.metrics is not None:
            logger.log(0, self.metrics)


def prepare_warm_start(
    cur: ResolvedCurriculum, agent: PPOAgent, run_dir: Path, seed: int, resumed: bool, progress: bool
) -> WarmStart | None:
    """Load or generate the demos and apply them to `agent`; writes no file. Bad demos (wrong
    stage or observation size, no successful episode) are a `SpecError` at `warm_start.*`."""
    ws = cur.spec.warm_start
    if ws is None:
        return None
    file = cur.file
    phase = cur.phases[ws.phase]
    saved = run_dir / DEMOS_FILE
    generated = ws.demos is None
    if not generated:
        try:
            demos = demo_io.load(cur.demos_file)
        except SpecError as exc:
            raise SpecError.single(file, "warm_start.demos", "; ".join(str(i) for i in exc.issues)) from None
        recorded = demos.metadata.get("stage")
        if ws.stage is not None and recorded != ws.stage:
            raise SpecError.single(file, "warm_start.stage", f"'{ws.stage}', but {cur.demos_file} holds demos of stage '{recorded}'")
    elif resumed and saved.is_file():
        demos = demo_io.load(saved)
    else:
        stage = ws.stage or phase.stages[-1]
        demos = demo_io.generate(phase.task_file, stage, ws.generate_episodes, seed=seed, split="train", progress=progress)
        if demos.num_steps == 0:
            raise SpecError.single(
                file, "warm_start.generate_episodes",
                f"no scripted episode of stage '{stage}' succeeded out of {ws.generate_episodes}; no demos to learn from",
            )
    size = agent.obs_normalizer.rms.mean.shape[0]
    if demos.observations.shape[1] != size:
        where = "warm_start.demos" if ws.demos else "warm_start.phase"
        raise SpecError.single(file, where, f"demo observations have {demos.observations.shape[1]} floats; the policy reads {size}")

    metrics = None
    if not resumed:
        rewards = scaled_rewards(agent, demos.rewards, demos.episode_starts, demos.terminated)
        targets = returns_to_go(rewards, demos.episode_starts, demos.truncated, agent.spec.ppo.gamma)
        metrics = pretrain(
            agent, demos.observations, demos.actions, targets, epochs=ws.bc_epochs, batch_size=ws.bc_batch_size,
            learning_rate=ws.bc_learning_rate, privileged=demos.privileged,
        )
        metrics["bc_demo_episodes"] = float(demos.num_episodes)
    if ws.regularizer.weight > 0:
        agent.set_demo_regularizer(demos.observations, demos.actions, ws.regularizer.weight, ws.regularizer.decay)
    return WarmStart(demos, generated, metrics)
