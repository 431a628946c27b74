"""`taskforge eval`: load a run (`taskforge.run.load_run`), evaluate every (task, stage) of its curriculum on a
split in trials (one per goal), print a table with the adaptation curve and write JSON."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from taskforge.rollouts import StageResult, evaluate_rows
from taskforge.run import load_run
from taskforge.spec import SpecError


def evaluate_run(
    path: str | Path,
    split: str = "test",
    trials: int = 20,
    stages: list[str] | None = None,
    seed: int = 0,
    trial_episodes: int | None = None,
    deterministic: bool = True,
    stop_on_success: bool = False,
) -> dict[str, Any]:
    """Evaluate a run: `trials` trials per (task, stage), trial k on goal k of the split, each of
    `trial_episodes` episodes (default the agent's: K for RL², 1 for PPO), acting with the
    policy's mean or (`deterministic` False) sampling from it. `stop_on_success` ends each episode
    at its first success, as training's evaluation does with `evaluation.stop_on_success`: the
    same success rate in fewer steps, which matters where every step is a plan (`algo: mpc`)."""
    run = load_run(path)
    agent = run.agent
    k = trial_episodes or agent.spec.trial_episodes
    rows: list[StageResult] = []
    for (task, task_file, phase_stages), sub_task_names in zip(run.phases, run.shapes.task_names):
        names = phase_stages if not stages else [s for s in phase_stages if s in stages]
        sub_tasks = sub_task_names if len(sub_task_names) > 1 else [None]
        if names:
            rows += evaluate_rows(agent, task, task_file, [(stage, sub) for stage in names for sub in sub_tasks], split,
                                  trials, k, seed=seed, deterministic=deterministic, stop_on_success=stop_on_success)
    if stages and not rows:
        known = sorted({s for _, _, phase_stages in run.phases for s in phase_stages})
        raise SpecError.single(run.checkpoint, "stage", f"none of {', '.join(stages)} is in this run; expected one of {', '.join(known)}")
    return {
        "checkpoint": str(run.checkpoint),
        "step": agent.global_step,
        "algo": agent.spec.algo,
        "split": split,
        "trials_per_row": trials,
        "trial_episodes": k,
        "actions": "mean" if deterministic else "sampled",
        "stop_on_success": stop_on_success,
        "rows": [r.as_dict() for r in rows],
    }


def after_a_miss(after_first_episode: dict[str, dict] | None) -> str:
    """The table cell for a row's `after_first_episode`: success of episodes 2..K after a missed
    first episode and how many trials that is, or "-" where no first episode missed (or the
    report has no split: trials of one episode)."""
    miss = (after_first_episode or {}).get("miss")
    if not miss or not miss["trials"]:
        return "-"
    return f"{miss['success_rate']:.2f} ({miss['trials']} trials)"


def format_table(report: dict[str, Any]) -> str:
    """One row per (task, stage); with trials of K > 1 episodes, also the success of episode 1
    and episode K of the trials (the two ends of the adaptation curve) and the success of
    episodes 2..K after a first episode that failed (what searching elsewhere gains). Under the
    table, each row's goals (indices into the split) on which no episode of a trial succeeded."""
    k = report["trial_episodes"]
    header = ["task", "stage", "success", "95% CI"]
    header += ["episode 1", f"episode {k}", "later, after a miss"] if k > 1 else []
    header += ["mean return", "mean length", "episodes"]

    def cells(r: dict[str, Any]) -> list[str]:
        row = [r["task"], r["stage"], f"{r['success_rate']:.2f}", f"[{r['success_ci95'][0]:.2f}, {r['success_ci95'][1]:.2f}]"]
        if k > 1:
            row += [f"{r['per_episode'][i]['success_rate']:.2f}" for i in (0, -1)]
            row.append(after_a_miss(r.get("after_first_episode")))
        return row + [f"{r['mean_return']:.1f}", f"{r['mean_length']:.0f}", str(r["episodes"])]

    lines = [cells(r) for r in report["rows"]]
    widths = [max(len(x) for x in col) for col in zip(header, *lines)]
    trials = f", trials of {k} episodes" if k > 1 else ""
    sampled = ", sampled actions" if report.get("actions") == "sampled" else ""
    out = [f"{report['checkpoint']} at step {report['step']:,}, {report['split']} split{trials}{sampled}"]
    out.append("  ".join(h.ljust(w) for h, w in zip(header, widths)))
    out.append("  ".join("-" * w for w in widths))
    out += ["  ".join(c.ljust(w) for c, w in zip(row, widths)) for row in lines]
    out += [f"missed goals, {r['task']} {r['stage']}: {', '.join(map(str, r['missed_goals']))}"
            for r in report["rows"] if r.get("missed_goals")]
    return "\n".join(out)
