"""`taskforge eval`: load a checkpoint, evaluate every (task, stage) of its curriculum on a
split in trials (one per goal), print a table with the adaptation curve and write JSON."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from taskforge.agents import PPOAgent, agent_observation_space
from taskforge.envs import PhaseShapes, probe_phases
from taskforge.evaluation.evaluate import StageResult, evaluate
from taskforge.spec import AgentSpec, SpecError, TaskSpec

CHECKPOINT_NAMES = ("final.pt", "checkpoint.pt")


def find_checkpoint(path: str | Path) -> Path:
    """A run directory (its final policy, else its last checkpoint) or a checkpoint file."""
    path = Path(path)
    if path.is_dir():
        for name in CHECKPOINT_NAMES:
            if (path / name).is_file():
                return path / name
        raise SpecError.single(path, "", f"no {' or '.join(CHECKPOINT_NAMES)} in this run directory")
    if not path.is_file():
        raise SpecError.single(path, "", "no such run directory or checkpoint file")
    return path


def load_agent(checkpoint: Path) -> tuple[PPOAgent, dict[str, Any], PhaseShapes]:
    """The agent of a checkpoint, the run config stored with it (tasks included, so the original
    YAML files need not exist any more) and the phases' shapes and sub-task names."""
    try:
        state = torch.load(checkpoint, map_location="cpu", weights_only=False)
        config = state["config"]
    except Exception as exc:  # not a taskforge checkpoint, or a truncated file
        raise SpecError.single(checkpoint, "", f"not a readable taskforge checkpoint ({exc.__class__.__name__}: {exc})") from None
    agent_spec = AgentSpec.model_validate(config["agent"])
    phases = [(TaskSpec.model_validate(p["task"]), p["task_file"]) for p in config["phases"]]
    shapes = probe_phases(phases, agent_spec.asymmetric_critic, checkpoint)
    obs_space = agent_observation_space(agent_spec, shapes.observation_space, shapes.action_space)
    agent = PPOAgent(agent_spec, obs_space, shapes.action_space, shapes.privileged_size, seed=config["seed"])
    agent.load_state_dict(state["agent"])
    return agent, config, shapes


def evaluate_run(
    path: str | Path,
    split: str = "test",
    trials: int = 20,
    stages: list[str] | None = None,
    seed: int = 0,
    trial_episodes: int | None = None,
    deterministic: bool = True,
) -> dict[str, Any]:
    """Evaluate a run: `trials` trials per (task, stage), trial k on goal k of the split, each of
    `trial_episodes` episodes (default the agent's: K for RL², 1 for PPO), acting with the
    policy's mean or (`deterministic` False) sampling from it."""
    checkpoint = find_checkpoint(path)
    agent, config, shapes = load_agent(checkpoint)
    k = trial_episodes or agent.spec.trial_episodes
    rows: list[StageResult] = []
    for phase, sub_task_names in zip(config["phases"], shapes.task_names):
        task = TaskSpec.model_validate(phase["task"])
        names = phase["stages"] if not stages else [s for s in phase["stages"] if s in stages]
        sub_tasks = sub_task_names if len(sub_task_names) > 1 else [None]
        for stage in names:
            for sub in sub_tasks:
                rows.append(evaluate(agent, task, phase["task_file"], stage, split, trials, k, sub_task=sub, seed=seed,
                                     deterministic=deterministic))
    if stages and not rows:
        known = sorted({s for p in config["phases"] for s in p["stages"]})
        raise SpecError.single(checkpoint, "stage", f"none of {', '.join(stages)} is in this run; expected one of {', '.join(known)}")
    return {
        "checkpoint": str(checkpoint),
        "step": agent.global_step,
        "algo": agent.spec.algo,
        "split": split,
        "trials_per_row": trials,
        "trial_episodes": k,
        "actions": "mean" if deterministic else "sampled",
        "rows": [r.as_dict() for r in rows],
    }


def format_table(report: dict[str, Any]) -> str:
    """One row per (task, stage); with trials of K > 1 episodes, also the success of episode 1
    and episode K of the trials (the two ends of the adaptation curve)."""
    k = report["trial_episodes"]
    header = ["task", "stage", "success", "95% CI"]
    header += ["episode 1", f"episode {k}"] if k > 1 else []
    header += ["mean return", "mean length", "episodes"]

    def cells(r: dict[str, Any]) -> list[str]:
        row = [r["task"], r["stage"], f"{r['success_rate']:.2f}", f"[{r['success_ci95'][0]:.2f}, {r['success_ci95'][1]:.2f}]"]
        if k > 1:
            row += [f"{r['per_episode'][i]['success_rate']:.2f}" for i in (0, -1)]
        return row + [f"{r['mean_return']:.1f}", f"{r['mean_length']:.0f}", str(r["episodes"])]

    lines = [cells(r) for r in report["rows"]]
    widths = [max(len(x) for x in col) for col in zip(header, *lines)]
    trials = f", trials of {k} episodes" if k > 1 else ""
    sampled = ", sampled actions" if report.get("actions") == "sampled" else ""
    out = [f"{report['checkpoint']} at step {report['step']:,}, {report['split']} split{trials}{sampled}"]
    out.append("  ".join(h.ljust(w) for h, w in zip(header, widths)))
    out.append("  ".join("-" * w for w in widths))
    out += ["  ".join(c.ljust(w) for c, w in zip(row, widths)) for row in lines]
    return "\n".join(out)
