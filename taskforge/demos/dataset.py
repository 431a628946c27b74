"""Recording demonstrations through a `TaskEnv`, and the `.npz` files that hold them.

What is stored is what the agent will train on: per step, the observation the *agent* sees
(observation noise and goal hiding included; the scripted policy itself acts on the true state)
and the action in the agent's action space (clipped to the env's box, before the env's action
noise and latency), plus the reward of the stage, its success flag, and the episode boundaries.

File layout (`np.savez_compressed`; `load` checks it):

| key | shape | meaning |
|---|---|---|
| `observations` | `[N, obs]` float32 | agent observation before each action |
| `actions` | `[N, act]` float32 | the action taken, in `[-1, 1]` |
| `rewards` | `[N]` float32 | the stage's reward for that step |
| `successes` | `[N]` bool | the stage's success condition after that step |
| `episode_starts` | `[N]` bool | first step of an episode |
| `terminated`, `truncated` | `[N]` bool | how the episode ended (on its last step) |
| `privileged` | `[N, p]` float32 | `info["privileged"]` before each action (an asymmetric critic's extra input); absent when not recorded |
| `episode_lengths`, `episode_success`, `goal_indices` | `[E]` | per episode kept |
| `final_observations` | `[E, obs]` float32 | agent observation after each episode's last step (absent in files recorded before it was kept) |
| `metadata` | 0-d str | JSON: task file and name, stage, split, seed, policy, success rate, taskforge version, ... |
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from taskforge.atomic import atomic_write
from taskforge.demos.policies import ScriptedPolicy, Source, act_in_box, scripted_policy
from taskforge.envs import TaskEnv, make
from taskforge.spec import SpecError

STEP_KEYS = ("observations", "actions", "rewards", "successes", "episode_starts", "terminated", "truncated")
EPISODE_KEYS = ("episode_lengths", "episode_success", "goal_indices")
OPTIONAL_KEYS = ("privileged", "final_observations")


@dataclass
class Demos:
    """A set of recorded episodes, steps concatenated in order (see the module doc)."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    successes: np.ndarray
    episode_starts: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    episode_lengths: np.ndarray
    episode_success: np.ndarray
    goal_indices: np.ndarray
    privileged: np.ndarray | None = None
    final_observations: np.ndarray | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def num_steps(self) -> int:
        return len(self.actions)

    @property
    def num_episodes(self) -> int:
        return len(self.episode_lengths)

    def arrays(self) -> dict[str, np.ndarray]:
        out = {k: getattr(self, k) for k in (*STEP_KEYS, *EPISODE_KEYS)}
        for key in OPTIONAL_KEYS:
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out

    def next_observations(self) -> np.ndarray:
        """`[N, obs]`: the observation after each step (the next step's, or the episode's final one).

        Why: a transition (s, a, s') is what a dynamics model is judged on; without the final
        observation an episode's last step has no s' (`benchmarks/mpc_push_probe.py` scores a
        model on every step a scripted push moved the puck, the last ones included)."""
        if self.final_observations is None:
            raise ValueError("these demos keep no final observations (recorded before they were kept); record them again")
        after = np.roll(self.observations, -1, axis=0)
        after[np.cumsum(self.episode_lengths) - 1] = self.final_observations
        return after


def record(
    env: TaskEnv,
    policy: ScriptedPolicy | None = None,
    episodes: int = 10,
    seed: int = 0,
    keep_failed: bool = False,
    progress: bool = False,
) -> Demos:
    """Run `episodes` episodes of the env's current stage with a scripted policy (default:
    `scripted_policy(env)`) and keep the successful ones (all with `keep_failed`).

    Episode k resets with `seed + k` on goal `(seed + k) mod number-of-goals` of the env's split,
    so a seed fixes the whole dataset and consecutive episodes visit different goals. A task set's
    sub-tasks take turns, and each walks its own goals in order (goal `(seed + k // tasks) mod
    number-of-goals`): indexing goals by k alone would give MT10's ten tasks only five of their
    fifty goals each, as 10 divides 50. An episode counts as successful when the stage's condition
    held at some step (`episode_success`).
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1 (got {episodes})")
    stage = env.stage
    policy = policy or scripted_policy(env, stage)
    num_goals = env.backend.num_goals(env.split)
    steps: dict[str, list] = {k: [] for k in (*STEP_KEYS, "privileged")}
    kept: dict[str, list] = {k: [] for k in (*EPISODE_KEYS, "final_observations")}
    successes = 0
    by_task: dict[str, list[bool]] = {}
    steps_run = 0  # failed episodes included: every step the expert took costs env time
    # a task set's sub-tasks in turn (MT10: every task as often), unless the env is pinned to one
    rotation = list(env.backend.task_names) if env.task_name is None and len(env.backend.task_names) > 1 else []
    bar = _progress_bar(episodes, f"{env.task.name}:{stage}", progress)
    for k in range(episodes):
        goal_index = (seed + k // max(1, len(rotation))) % num_goals
        options = {"stage": stage, "goal_index": goal_index, **({"task": rotation[k % len(rotation)]} if rotation else {})}
        obs, info = env.reset(seed=seed + k, options=options)
        policy.reset(env)
        episode: dict[str, list] = {key: [] for key in steps}
        while True:
            action = act_in_box(policy, env)
            episode["observations"].append(obs)
            episode["privileged"].append(info.get("privileged"))
            obs, reward, terminated, truncated, info = env.step(action)
            episode["actions"].append(action)
            episode["rewards"].append(reward)
            episode["successes"].append(info["success"])
            episode["terminated"].append(terminated)
            episode["truncated"].append(truncated)
            if terminated or truncated:
                break
        success = bool(info["episode_success"])
        successes += success
        by_task.setdefault(str(info["task"]), []).append(success)
        steps_run += len(episode["actions"])
        if success or keep_failed:
            length = len(episode["actions"])
            episode["episode_starts"] = [True] + [False] * (length - 1)
            for key in steps:
                steps[key] += episode[key]
            kept["episode_lengths"].append(length)
            kept["episode_success"].append(success)
            kept["goal_indices"].append(goal_index)
            kept["final_observations"].append(obs)
        if bar is not None:
            bar.set_postfix_str(f"success {successes}/{k + 1} ({successes / (k + 1):.0%})", refresh=False)
            bar.update(1)
    if bar is not None:
        bar.close()

    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    privileged = None
    if steps["privileged"] and steps["privileged"][0] is not None:
        privileged = np.asarray(steps["privileged"], dtype=np.float32)
    import taskforge

    metadata = {
        "format": "taskforge-demos/1",
        "taskforge_version": taskforge.__version__,
        "task_file": env.file,
        "task": env.task.name,
        "backend": env.task.backend.type,
        "stage": stage,
        "split": env.split,
        "seed": seed,
        "policy": getattr(policy, "name", type(policy).__name__),
        "episodes_run": episodes,
        "episodes_kept": len(kept["episode_lengths"]),
        "steps_run": steps_run,
        "successes": successes,
        "success_rate": successes / episodes,
        "success_by_task": {name: float(np.mean(v)) for name, v in by_task.items()},
        "keep_failed": keep_failed,
        "observation_size": obs_dim,
        "action_size": act_dim,
        "goal_hidden": not env.task.goals.observable,
        "max_episode_steps": env.max_episode_steps,
    }
    return Demos(
        observations=np.asarray(steps["observations"], dtype=np.float32).reshape(-1, obs_dim),
        actions=np.asarray(steps["actions"], dtype=np.float32).reshape(-1, act_dim),
        rewards=np.asarray(steps["rewards"], dtype=np.float32),
        successes=np.asarray(steps["successes"], dtype=bool),
        episode_starts=np.asarray(steps["episode_starts"], dtype=bool),
        terminated=np.asarray(steps["terminated"], dtype=bool),
        truncated=np.asarray(steps["truncated"], dtype=bool),
        episode_lengths=np.asarray(kept["episode_lengths"], dtype=np.int64),
        episode_success=np.asarray(kept["episode_success"], dtype=bool),
        goal_indices=np.asarray(kept["goal_indices"], dtype=np.int64),
        privileged=privileged,
        final_observations=np.asarray(kept["final_observations"], dtype=np.float32).reshape(-1, obs_dim),
        metadata=metadata,
    )


def concatenate(parts: list[Demos]) -> Demos:
    """Demos of several tasks as one set (a warm start over every phase of a curriculum): steps
    and episodes in order, `privileged` zero-padded to the widest part (the phases' physics draws
    may differ in number), and metadata that keeps each part's and sums what was run."""
    if len(parts) == 1:
        return parts[0]
    arrays = {k: np.concatenate([getattr(p, k) for p in parts]) for k in (*STEP_KEYS, *EPISODE_KEYS)}
    privileged = None
    blocks = [p.privileged for p in parts if p.privileged is not None]
    if len(blocks) == len(parts):
        width = max(b.shape[1] for b in blocks)
        privileged = np.concatenate([np.pad(b, ((0, 0), (0, width - b.shape[1]))) for b in blocks])
    finals = [p.final_observations for p in parts]
    final_observations = np.concatenate(finals) if all(f is not None for f in finals) else None  # type: ignore[arg-type]
    meta = [p.metadata for p in parts]
    run, ok = sum(m.get("episodes_run", p.num_episodes) for m, p in zip(meta, parts)), sum(m.get("successes", 0) for m in meta)
    by_task = {f"{m.get('task')}/{name}" if len(m.get("success_by_task", {})) > 1 else str(m.get("task")): rate
               for m in meta for name, rate in m.get("success_by_task", {}).items()}
    metadata = {
        "format": meta[0].get("format"),
        "task": " + ".join(str(m.get("task")) for m in meta),
        "stage": ", ".join(dict.fromkeys(str(m.get("stage")) for m in meta)),
        "episodes_run": run,
        "episodes_kept": int(arrays["episode_lengths"].size),
        "steps_run": sum(m.get("steps_run", p.num_steps) for m, p in zip(meta, parts)),
        "successes": ok,
        "success_rate": ok / run if run else 0.0,
        "success_by_task": by_task,
        "parts": meta,
    }
    return Demos(**arrays, privileged=privileged, final_observations=final_observations, metadata=metadata)


def generate(
    task_file: str | Path,
    stage: str | None = None,
    episodes: int = 10,
    seed: int = 0,
    split: str = "train",
    keep_failed: bool = False,
    source: Source = "auto",
    progress: bool = False,
) -> Demos:
    """Load a task file and `record` scripted demonstrations of one stage (default: the last).

    The env is built with `privileged=True`, so the demos carry `info["privileged"]` for an
    asymmetric critic. Raises `SpecError` for a bad task file, stage or split."""
    from taskforge.envs import load_task

    task = load_task(task_file)
    stage = stage or task.stages[-1].name
    env = make(task_file, stage=stage, split=split, privileged=True)  # type: ignore[arg-type]
    try:
        return record(env, scripted_policy(env, stage, source), episodes, seed, keep_failed, progress)
    finally:
        env.close()


def save(demos: Demos, path: str | Path) -> Path:
    """Write atomically: a temp file in the same folder, fsync, then `os.replace`, so a kill
    leaves the old file or the new one, never a torn one."""
    metadata = np.array(json.dumps(demos.metadata))
    return atomic_write(path, lambda f: np.savez_compressed(f, **demos.arrays(), metadata=metadata))


def load(path: str | Path) -> Demos:
    """Read a demos file; a missing, unreadable or malformed file is a `SpecError`."""
    path = Path(path)
    if not path.is_file():
        raise SpecError.single(path, "", "no such file; expected a demos .npz (taskforge demos TASK.yaml --out ...)")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError) as exc:
        raise SpecError.single(path, "", f"not a readable .npz file ({exc})") from None
    missing = [k for k in (*STEP_KEYS, *EPISODE_KEYS, "metadata") if k not in arrays]
    if missing:
        raise SpecError.single(path, "", f"not a taskforge demos file: missing {', '.join(missing)}")
    n = len(arrays["actions"])
    if any(len(arrays[k]) != n for k in STEP_KEYS) or int(arrays["episode_lengths"].sum()) != n:
        raise SpecError.single(path, "", "inconsistent demos file: per-step arrays and episode lengths disagree")
    if n == 0:
        raise SpecError.single(path, "", "holds no steps (every episode failed?); record it again, or with --keep-failed")
    return Demos(
        **{k: arrays[k] for k in (*STEP_KEYS, *EPISODE_KEYS)},
        **{k: arrays.get(k) for k in OPTIONAL_KEYS},
        metadata=json.loads(str(arrays["metadata"])),
    )


def _progress_bar(total: int, desc: str, enabled: bool):
    if not enabled:
        return None
    import sys

    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="episode", file=sys.stderr, dynamic_ncols=True)
