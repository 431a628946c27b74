"""The Gymnasium env that joins a backend, a stage's reward terms and success condition, and
the task's randomisation.

Per step: clip action -> action noise -> latency -> backlash -> backend.step -> features -> success ->
reward terms -> observation noise -> hide goal. Per reset: choose sub-task and goal from the
env's seeded generator -> restore+draw physics -> draw the object's start (if random) -> reset
noise/latency -> backend.reset.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.spaces import Box

from taskforge.backends import Backend, GoalOverride, Split, make_backend
from taskforge.backends.mujoco_common import diverged
from taskforge.randomization import ActionBacklash, ActionLatency, AdditiveNoise, PhysicsRandomizer
from taskforge.spec import SpecError, TaskSpec, expected_one_of
from taskforge.terms import FEATURES, GOAL_FEATURES, NATIVE_FEATURES, PROGRESS_FEATURES, CompiledStage, Features

SPLITS: tuple[Split, ...] = ("train", "test")
RELATIVE_FEATURES = frozenset({"tcp_pos", "object_pos", "goal_pos"})
RELATIVE_SIZE = 6
"""Floats `observation.relative_positions` appends: object - tool, goal - object."""


def _clip_unit(x: np.ndarray) -> np.ndarray:
    """`x` clipped to [-1, 1] (the action box)."""
    return np.minimum(np.maximum(x, -1.0), 1.0)


class TaskEnv(gym.Env[np.ndarray, np.ndarray]):
    """One task file as a Gymnasium env, running one stage at a time.

    `reset(options={"stage": ..., "task": ..., "goal_index": ..., "replay": ...})` switches the
    stage, the sub-task of a task set, or pins the goal for that episode (`replay` is only echoed
    back in `info`); this is how a curriculum drives vectorised workers without rebuilding them.
    `reset(options={"same_task": True})` starts another episode of the previous one's stage,
    sub-task and goal with the same physics draw and object start (noise processes restart):
    RL²'s trials.

    A vectorised trainer cannot pass options through autoreset, so it sets `next_episode`
    (e.g. with `VectorEnv.set_attr`) to the options the *next* reset without options should use.

    `info` on every step carries `success` (the stage's condition this step), `episode_success`
    (it held at some step of this episode: Meta-World's convention), `native_success` (the
    suite's own flag; on Meta-World only while the backend computes it: `native`), `reward_terms` (each term's unweighted value), `stage`, `task` and
    `goal_index`; `unstable` on the step that ended an episode whose simulation blew up (see
    `_unstable_step`); on an episode's last step also `episode_reward_terms` (each term's weighted sum
    over the episode: what the stage's weights made of it, Isaac Lab's `Episode_Reward/<term>`); with `privileged=True` also `privileged` (object velocity, true goal and the
    physics draws), for an asymmetric critic.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        task: TaskSpec,
        file: str | Path = "<task>",
        stage: str | None = None,
        split: Split = "train",
        seed: int | None = None,
        task_name: str | None = None,
        privileged: bool = False,
        end_on_success: bool = False,
        native: bool | None = None,
    ):
        """`native`: have the backend compute the suite's own reward and success every step
        (`native_*` features, `info["native_success"]`); None: only when a stage reads them,
        since on Meta-World they are ~40 % of a step."""
        if split not in SPLITS:
            raise SpecError.single(file, "split", f"unknown split '{split}'; expected train or test")
        self.task = task
        self.file = str(file)
        self.split: Split = split
        self.privileged = privileged
        self.end_on_success = end_on_success
        """Terminate every episode at its first success, whatever the stage says (evaluation)."""
        self.backend: Backend = make_backend(task, file)
        self.stages = {s.name: CompiledStage(s, file, f"stages[{i}]") for i, s in enumerate(task.stages)}
        self.stage = self._check_stage(stage or task.stages[0].name)
        self._observed = self._check_observed(task.observation.features)
        if native is None:
            native = any(s.reads & NATIVE_FEATURES for s in self.stages.values()) or not NATIVE_FEATURES.isdisjoint(self._observed)
        self.backend.native = native
        self.task_name = self._check_task_name(task_name)
        # One per sub-task with a MuJoCo model (other backends' checks reject physics terms),
        # built now so that bad `names` fail at construction, not mid-run.
        self._randomizers: dict[str, PhysicsRandomizer] = {
            name: PhysicsRandomizer(model, task.randomization.physics, self.backend.object_geoms(name), self.file)
            for name in self.backend.task_names
            if (model := self.backend.model(name)) is not None
        }

        rand = task.randomization
        n_act = self.backend.action_space.shape[0]
        self._relative = task.observation.relative_positions
        if self._relative and not RELATIVE_FEATURES <= self.backend.provides:
            missing = ", ".join(sorted(RELATIVE_FEATURES - self.backend.provides))
            raise SpecError.single(file, "observation.relative_positions", f"the {task.backend.type} backend does not provide {missing}")
        base_size = sum(FEATURES[f].size for f in self._observed) if self._observed else self.backend.obs_size
        obs_size = base_size + (RELATIVE_SIZE if self._relative else 0)
        self._obs_noise = AdditiveNoise(rand.observation_noise, obs_size)
        self._act_noise = AdditiveNoise(rand.action_noise, n_act)
        self._latency = ActionLatency(rand.action_latency, n_act)
        self._backlash = ActionBacklash(rand.action_backlash, n_act)
        self._hide_goal = not task.goals.observable
        self._random_object = rand.object_start == "random"
        self._fresh_train = task.goals.train.draw == "fresh"
        self._task_seed = 0

        self.action_space = Box(-1.0, 1.0, (n_act,), np.float32)
        self.observation_space = Box(-np.inf, np.inf, (obs_size,), np.float32)
        self._seed = seed
        self.next_episode: dict[str, Any] | None = None
        self._episode: dict[str, Any] = {}
        self._t = 0
        self._ever_success = False
        self._held = 0
        """Steps in a row the stage's conditions have held (`success.hold_steps`)."""
        read = frozenset().union(*(s.reads for s in self.stages.values()))
        self._progress = {p: d for p, d in PROGRESS_FEATURES.items() if p in read and d in self.backend.provides}
        """Progress features some stage reads, each with its distance: only they cost a step."""
        self._closest: dict[str, float] = {}
        """Each progress feature's record: the smallest distance so far this episode."""

    # -- configuration ------------------------------------------------------------------------

    def _check_observed(self, names: list[str] | None) -> tuple[str, ...]:
        """`observation.features`, checked against what this backend fills every step (with a
        known size) and, with the goal hidden, against the features that would reveal it."""
        if names is None:
            return ()
        valid = {n for n in self.backend.provides if FEATURES[n].size > 0}
        for i, name in enumerate(names):
            field = f"observation.features[{i}]"
            if name not in valid:
                raise SpecError.single(self.file, field, f"'{name}' is not a feature the {self.task.backend.type} backend observes; {expected_one_of(name, valid)}")
            if not self.task.goals.observable and name in GOAL_FEATURES:
                raise SpecError.single(self.file, field, f"'{name}' depends on the goal, which this task hides (goals.observable: false)")
        return tuple(names)

    def _check_stage(self, stage: str) -> str:
        if stage not in self.stages:
            raise SpecError.single(self.file, "stage", f"no stage '{stage}'; {expected_one_of(stage, self.stages)}")
        return stage

    def _check_task_name(self, name: str | None) -> str | None:
        if name is not None and name not in self.backend.task_names:
            msg = f"no sub-task '{name}'; {expected_one_of(name, self.backend.task_names)}"
            raise SpecError.single(self.file, "task", msg)
        return name

    @property
    def max_episode_steps(self) -> int:
        return self.task.episode_steps(self.stages[self.stage].spec)

    # -- gymnasium API ------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is None and self._seed is not None:
            seed, self._seed = self._seed, None  # the constructor's seed seeds the first reset
        super().reset(seed=seed)
        options = options or self.next_episode or {}
        same_task = bool(options.get("same_task"))
        if same_task:
            if not self._episode:
                raise RuntimeError("reset(options={'same_task': True}) needs an earlier reset to repeat")
            options = self._episode
        if "stage" in options:
            self.stage = self._check_stage(options["stage"])
        rng = self.np_random
        name = self._check_task_name(options.get("task")) or self.task_name
        if name is None:
            name = self.backend.task_names[int(rng.integers(len(self.backend.task_names)))]
        goal_index = options.get("goal_index")
        if goal_index is None:
            goal_index = int(rng.integers(self.backend.num_goals(self.split)))

        # Whether this task instance draws something (an object start, a fresh training goal):
        # the env then draws a seed per instance, and the backend its draws from that seed.
        draws_task = self._random_object or (self._fresh_train and self.split == "train")
        randomizer = self._randomizers.get(name)
        if same_task:  # the model still holds the previous draw: the task includes its physics
            physics_draw = self._physics_draw
        else:
            physics_draw = randomizer.apply(rng) if randomizer else np.zeros(0)
            if draws_task:
                # A seed, not a position: the backend owns its regions and the minimum distance
                # between object and goal; `same_task` hands it the same seed to repeat the task.
                self._task_seed = int(rng.integers(2**63))
        self._obs_noise.reset(rng)
        self._act_noise.reset(rng)
        self._latency.reset(rng)
        self._backlash.reset(rng)

        stage = self.stages[self.stage]
        goal = GoalOverride(stage.spec.goal.height, stage.spec.goal.distance_scale, stage.spec.goal.height_scale)
        task_rng = np.random.default_rng(self._task_seed) if draws_task else None
        obs = self.backend.reset(name, self.split, goal_index, goal, task_rng)
        self._t = 0
        # `replay` is the curriculum's label for the episode, echoed back so a trainer can tell
        # which finished episodes were replays without tracking autoresets itself.
        self._episode = {"stage": self.stage, "task": name, "goal_index": goal_index, "replay": bool(options.get("replay", False))}
        self._ever_success = False
        self._held = 0
        self._reward_sums = dict.fromkeys((t.key for t in self.stages[self.stage].terms), 0.0)
        self._physics_draw = physics_draw
        features = self.backend.features()
        features["action"] = np.zeros(self.action_space.shape[0])
        self._closest = {p: features[d] for p, d in self._progress.items()}
        features.update(dict.fromkeys(self._progress, 0.0))
        info = self._info(features, stage.success(features) and stage.hold_steps == 1, {})
        return self._observe(obs, features), info

    def step(self, action: np.ndarray):
        # Runs every step: finiteness by one sum (NaN/inf in, NaN/inf out) and clipping by
        # minimum/maximum, each several times cheaper than np.isfinite().all() / np.clip at this size.
        action = np.asarray(action, dtype=np.float64)
        finite_action = math.isfinite(action.sum())
        chosen = _clip_unit(action if finite_action else np.nan_to_num(action, nan=0.0))
        applied = self._backlash(self._latency(self._act_noise(chosen, self.np_random)))
        obs, ended = self.backend.step(_clip_unit(applied))
        self._t += 1

        features = self.backend.features()
        features["action"] = chosen
        for feature, distance in self._progress.items():
            now, record = features[distance], self._closest[feature]
            features[feature] = max(0.0, record - now)
            self._closest[feature] = min(record, now)
        stage = self.stages[self.stage]
        self._held = self._held + 1 if stage.success(features) else 0
        success = self._held >= stage.hold_steps
        features["stage_success"] = float(success)
        reward, terms = stage.reward(features)
        if not (finite_action and math.isfinite(reward) and math.isfinite(obs.sum()) and not self._diverged()):
            return self._unstable_step(obs, features, terms)
        self._ever_success |= success
        for term in stage.terms:
            self._reward_sums[term.key] += term.weight * terms[term.key]

        terminated = ended or (success and (stage.spec.terminate_on_success or self.end_on_success))
        truncated = self._t >= self.max_episode_steps
        info = self._info(features, success, terms)
        if terminated or truncated:
            info["episode_reward_terms"] = dict(self._reward_sums)
        return self._observe(obs, features), reward, terminated, truncated, info

    def _diverged(self) -> bool:
        data = self.backend.data
        return data is not None and diverged(data)

    def _unstable_step(self, obs: np.ndarray, features: Features, terms: dict[str, float]):
        """A non-finite action, reward or observation, or a MuJoCo simulation that blew up (extreme
        randomisation can do it): the episode ends here, truncated (its state is nonsense, not a
        terminal state to learn a value of), with reward 0 and a finite observation, and
        `info["unstable"]` so the trainer counts it. Nothing non-finite reaches the agent."""
        info = self._info(features, False, dict.fromkeys(terms, 0.0))
        info.update(unstable=True, episode_reward_terms=dict(self._reward_sums))
        obs = np.nan_to_num(self._observe(obs, features), nan=0.0, posinf=0.0, neginf=0.0)
        return obs, 0.0, False, True, info

    def _observe(self, obs: np.ndarray, features: Features) -> np.ndarray:
        if self._observed:  # only the named features (see ObservationSpec.features); none reveals a hidden goal
            obs = np.concatenate([np.atleast_1d(features[f]) for f in self._observed]).astype(np.float64)
        if self._relative:  # object - tool, goal - object (see ObservationSpec.relative_positions)
            tcp, obj, goal = features["tcp_pos"], features["object_pos"], features["goal_pos"]
            obs = np.concatenate([obs, obj - tcp, goal - obj])
        obs = self._obs_noise(obs, self.np_random)
        if self._hide_goal:
            if not self._observed:
                obs[self.backend.goal_slice] = 0.0
            if self._relative:
                obs[-3:] = 0.0  # goal - object would give the hidden goal away
        return obs.astype(np.float32)

    def _info(self, features: Features, success: bool, terms: dict[str, float]) -> dict[str, Any]:
        info = {
            **self._episode,
            "success": success,
            "episode_success": self._ever_success,
            "reward_terms": terms,
        }
        if "native_success" in features:
            info["native_success"] = features["native_success"]
        if self.privileged:
            out = np.zeros(self.privileged_size, dtype=np.float32)
            velocity, goal = features.get("object_velocity", ()), features.get("goal_pos", ())
            parts = np.concatenate([velocity, goal, self._physics_draw])
            out[: parts.size] = parts  # sub-tasks of a set may draw fewer numbers: zero-padded
            info["privileged"] = out
        return info

    @property
    def privileged_size(self) -> int:
        """Length of `info["privileged"]`: object velocity and goal (when the backend has them)
        and the largest number of physics draws of any sub-task."""
        draws = max((r.draw_size for r in self._randomizers.values()), default=0)
        own = sum(FEATURES[f].size for f in ("object_velocity", "goal_pos") if f in self.backend.provides)
        return own + draws

    def features(self) -> Features:
        """The current features (for scripted policies, tests and debugging)."""
        return self.backend.features()

    def close(self) -> None:
        for rnd in self._randomizers.values():
            rnd.restore()
        self.backend.close()
