"""`algo: mpc`: model-based RL as GenReL-World frames it and PETS (Chua et al. 2018) does it: a
learned model f(s, a) -> (s', r) (`dynamics.py`), and at every step a planner (`planners.py`)
that picks the action sequence with the highest predicted return and executes its first action.

Reading order of one training iteration (the trainer drives it like PPO: `collect`, `update`):

1. `collect`: `steps_per_update` env steps. The first `random_steps` take uniform random actions
   (PETS's random first trial; none where the data came from elsewhere); then the planner,
   warm-started from each env's previous plan shifted by one step. Every transition
   (observation, action, stage reward, next observation; the true last observation of an episode
   that ended, from `final_obs`) goes into the buffer, tagged with its episode's stage.
2. `update`: standardisation statistics refitted on the whole buffer, then `model_updates`
   Adam steps, each member on its own bootstrap draw of `batch_size` transitions; with
   `terminal_value`, as many TD(0) steps on the value (`value.py`) that scores plans' last states,
   or with `value_policy` as many TD3+BC steps on TD-MPC's `Q(s, pi(s))` (`policy_value.py`)
   (with `value_refit_every`, now and then a fresh one fitted on the whole buffer instead;
   with `value_start`, none before that many env steps, and plans score rewards alone till then).
   The motion is learnt from every transition, the reward and the value from those of the stage
   being trained (that of the latest episode started, replays of earlier stages aside). Why: a
   curriculum changes the reward, not the physics, and the rows of an earlier stage carry its
   reward on the same states. Measured on Meta-World push after reach (~16k steps): fitted on
   every row, the reward's squared error rose 40x at the promotion and stayed there (~0.013),
   where the push stage alone fits it to ~0.0001. With `value_relabel` the value reads every
   row, the earlier stages' with the reward the model's reward network gives them for this
   stage (a first fit soon after a promotion otherwise has only the few rows since).

Why the agent has the same surface as `PPOAgent` (`collect`, `update`, `act`, `state_dict`):
the curriculum, checkpoints, `--resume`, the progress bar and `taskforge eval` then work
unchanged. `act` carries each env's plan in the slot where a recurrent policy carries its state,
so evaluation's episode starts reset it. Termination is not modelled: every shipped stage ends by
its time limit or on success, and a planned trajectory past success only adds reward.

With `prior_trajectories`, a policy cloned from the warm start's demos (`prior.py`, MoDem's
recipe), or with `value_policy` the value's own policy, learnt on the buffer (TD-MPC's
policy-guided trajectories), proposes that many sequences at every step: it is stepped through the model's mean for
`horizon` steps from the env's observation, and its actions join each planning round's
candidates. With `search_from_prior` (the default) the search then starts from the prior's own
(noise-free) rollout instead of the previous plan (LOOP's actor-guided optimisation, Sikchi et
al. 2021): a trust region of
`init_std` around what the demos do. Why: on pick-place, a model fitted on demos alone predicts
reward for lifting the hand whether or not it holds the object (in the demos it always does);
a search from the previous plan found that and rose to the ceiling, 0 of 8 held-out goals, the
prior's rollout scoring best in 4 % of the steps; started from the prior, 8 of 8 at
`init_std` 0.1 and 5 of 8 at 0.25 (benchmarks/RESULTS.md). A policy that learns from scratch
is poor early, and a search restarted from it every step loses its own progress: with
`value_policy` on push, reach was never learnt to 19k steps that way, and was from the previous
plan (agents/mpc_policy_value.yaml sets `search_from_prior: false`, TD-MPC's arrangement).

`mpc.device` puts the model, the value and the planner on a GPU; the buffer, the bootstrap
draws and the random first actions stay on the CPU with `generator`, so the networks start
from the same weights and see the same batches on either device. On a GPU the planner's and the
model's noise come from `plan_generator`, a generator there (a CPU generator cannot feed CUDA
draws); on the CPU it is `generator` itself, one stream as before the option existed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import numpy as np
import torch
from gymnasium.spaces import Box
from gymnasium.vector import VectorEnv

from taskforge.agents.dynamics import DynamicsEnsemble
from taskforge.agents.planners import plan, shift
from taskforge.agents.policy_value import PolicyValue
from taskforge.agents.prior import PolicyPrior
from taskforge.agents.runtime import check_same_step_autoreset, torch_threads, update_threads
from taskforge.agents.value import TerminalValue
from taskforge.agents.weights import WeightsMismatch, load_matching, require
from taskforge.spec.agent import AgentSpec

OnStep = Callable[[np.ndarray, np.ndarray, np.ndarray, dict], None]
UNTAGGED = -1  # a transition whose stage is not known (`TransitionBuffer`)
RELABEL_CHUNK = 16_384  # rows per forward pass when relabelling rewards (`MPCAgent._stage_rewards`)


def _stage_of(info: dict, i: int) -> str | None:
    """Env i's `stage` in a vector env's info (gymnasium masks each key by `_<key>`); None where
    it names none (a plain gymnasium env)."""
    if "stage" not in info or not info.get("_stage", np.ones(i + 1, bool))[i]:
        return None
    return str(info["stage"][i])


class TransitionBuffer:
    """The model's data: the last `capacity` transitions, oldest overwritten first, each tagged
    with the stage whose reward it carries (an index into the agent's `stage_names`; -1: none
    named, as in checkpoints from before the tags)."""

    def __init__(self, capacity: int, obs_size: int, action_size: int):
        self.capacity = capacity
        self.obs = torch.zeros((capacity, obs_size))
        self.actions = torch.zeros((capacity, action_size))
        self.rewards = torch.zeros(capacity)
        self.next_obs = torch.zeros((capacity, obs_size))
        self.stages = torch.full((capacity,), UNTAGGED, dtype=torch.int16)
        self.size = self.cursor = 0

    def add(self, obs: np.ndarray, actions: np.ndarray, rewards: np.ndarray, next_obs: np.ndarray, stages: np.ndarray) -> None:
        for row in zip(obs, actions, rewards, next_obs):
            i = self.cursor
            self.obs[i], self.actions[i], self.rewards[i], self.next_obs[i] = (torch.as_tensor(np.asarray(x), dtype=torch.float32) for x in row)
            self.cursor = (i + 1) % self.capacity
            self.size = min(self.size + 1, self.capacity)
        tags = torch.as_tensor(np.asarray(stages), dtype=torch.int16)[-self.capacity:]  # what the rows kept
        first = (self.cursor - len(tags)) % self.capacity
        self.stages[(first + torch.arange(len(tags))) % self.capacity] = tags

    def oldest_first(self) -> torch.Tensor:
        """Row indices of the filled part in the order they were collected: once the buffer is
        full, the oldest row is the one the cursor overwrites next."""
        rows = torch.arange(self.size)
        return torch.roll(rows, -self.cursor) if self.size == self.capacity else rows

    def rows_of(self, stage: int | None) -> torch.Tensor:
        """Indices of the filled rows whose reward is `stage`'s (untagged rows count as any
        stage's); all of them where `stage` is None (no stage named yet)."""
        tags = self.stages[: self.size]
        if stage is None:
            return torch.arange(self.size)
        return torch.nonzero((tags == stage) | (tags == UNTAGGED)).flatten()

    def inputs_and_targets(self, idx: torch.Tensor | slice = slice(None)) -> tuple[torch.Tensor, torch.Tensor]:
        """(obs, action) and (next_obs - obs, reward) of the rows `idx` (of the filled part)."""
        obs, act = self.obs[: self.size][idx], self.actions[: self.size][idx]
        targets = torch.cat([self.next_obs[: self.size][idx] - obs, self.rewards[: self.size][idx, None]], dim=-1)
        return torch.cat([obs, act], dim=-1), targets

    def state_dict(self) -> dict:
        """The filled rows, each `next_obs` that repeats a row's `obs` bit for bit saved as that
        row's index (`landed_at`; -1 where it repeats none: the rows an episode ended on, saved in
        `next_obs`). Why: while an env's episode goes on, where it landed is its next row's
        observation, so a plain copy saves every observation twice, and a long benchmark that spans
        sessions resumes from a committed checkpoint (benchmarks/RESULTS.md): this halves it,
        losslessly."""
        n = self.size
        obs, landed = self.obs[:n].numpy(), self.next_obs[:n].numpy()
        row_of = {row.tobytes(): i for i, row in enumerate(obs)}
        landed_at = torch.as_tensor([row_of.get(row.tobytes(), -1) for row in landed], dtype=torch.int32)
        return {"obs": self.obs[:n].clone(), "actions": self.actions[:n].clone(), "rewards": self.rewards[:n].clone(),
                "landed_at": landed_at, "next_obs": self.next_obs[:n][landed_at < 0].clone(),
                "stages": self.stages[:n].clone(), "cursor": self.cursor}

    def load_state_dict(self, state: dict) -> None:
        n = len(state["rewards"])
        self.obs[:n], self.actions[:n], self.rewards[:n] = state["obs"], state["actions"], state["rewards"]
        landed_at = state.get("landed_at", torch.full((n,), -1, dtype=torch.int32))  # before the links: every row saved
        linked = landed_at >= 0
        self.next_obs[:n][linked] = self.obs[landed_at[linked].long()]
        self.next_obs[:n][~linked] = state["next_obs"]
        self.stages[:n] = state.get("stages", torch.full((n,), UNTAGGED, dtype=torch.int16))
        self.size, self.cursor = n, state["cursor"]


class MPCAgent:
    """A learned-model MPC agent with `PPOAgent`'s interface (see the module doc)."""

    def __init__(self, spec: AgentSpec, observation_space: Box, action_space: Box, privileged_dim: int = 0, seed: int = 0):
        self.spec, self.seed = spec, seed
        self.mpc = spec.planning
        self.observation_space, self.action_space = observation_space, action_space
        self.privileged_dim = 0  # the model reads observations only
        self.device = torch.device(self.mpc.device)
        self.generator = torch.Generator().manual_seed(seed)
        self.plan_generator = self.generator if self.device.type == "cpu" else torch.Generator(self.device).manual_seed(seed)
        obs_size, self.action_size = observation_space.shape[0], action_space.shape[0]
        self.model = DynamicsEnsemble(obs_size, self.action_size, self.mpc, self.generator).to(self.device)
        self.optimizer = torch.optim.Adam(self.model.parameters(), lr=self.mpc.learning_rate, weight_decay=self.mpc.weight_decay)
        self.buffer = TransitionBuffer(self.mpc.buffer_size, obs_size, self.action_size)
        self.value: TerminalValue | PolicyValue | None = None
        self.value_refits = 0  # fresh refits of the value so far (`mpc.value_refit_every`)
        # has the value had its first fit (`mpc.value_start`)? Until then plans score rewards alone
        self.value_started = self.mpc.value_start == 0
        self.prior: PolicyPrior | None = None
        if self.mpc.terminal_value:
            self._new_value()  # with `value_policy` and proposals, its policy is the prior
        if self.mpc.prior_trajectories and not self.mpc.value_policy:  # fitted by `fit_prior` at the warm start
            self.prior = PolicyPrior(obs_size, self.action_size, self.mpc.hidden_sizes, self.generator).to(self.device)
        self.low = torch.as_tensor(action_space.low, dtype=torch.float32, device=self.device)
        self.high = torch.as_tensor(action_space.high, dtype=torch.float32, device=self.device)
        self.global_step = 0
        self.num_updates = 0
        self.data_given = False  # demos or another run's buffer: no random first trial
        self.stage_names: list[str] = []  # the stages whose rewards the buffer holds, as first seen
        self.stage: int | None = None  # the stage being trained (module doc, 2.); None: none named yet
        self._obs: np.ndarray | None = None
        self._plans: torch.Tensor | None = None
        self._env_resets = 0

    # ----------------------------------------------------------------------------------- acting

    def initial_state(self, num_envs: int) -> torch.Tensor:
        """Each env's plan (`[envs, horizon, action]`, in [-1, 1]): the planner's warm start."""
        return torch.zeros((num_envs, self.mpc.horizon, self.action_size), device=self.device)

    def act(self, obs: np.ndarray, state: torch.Tensor | None = None, episode_start: np.ndarray | None = None,
            deterministic: bool = True) -> tuple[np.ndarray, torch.Tensor]:
        """Plan from each observation and return the plans' first actions in env units, and the
        plans shifted for the next step. `episode_start[i]` discards env i's previous plan. The
        search is random either way (`deterministic` is accepted for `evaluate`'s sake)."""
        obs_t = torch.as_tensor(np.atleast_2d(np.asarray(obs, dtype=np.float32)), device=self.device)
        with torch.no_grad():
            # a value's pi proposes once it is fitted (`mpc.value_start`); a demos' prior from the start
            proposing = self.prior is not None and (self.value_started or not self.mpc.value_policy)
            proposals = self._proposals(obs_t) if proposing else None
            if proposals is not None and self.mpc.search_from_prior:  # from the prior's own rollout (module doc)
                warm = proposals[:, 0]
            else:
                warm = self._previous_plans(state, episode_start, len(obs_t))
            new = plan(self.mpc, partial(self.score, obs_t), warm, self.plan_generator, proposals)
        return self._to_env(new[:, 0]), shift(new)

    def prior_act(self, obs: np.ndarray) -> np.ndarray:
        """The cloned prior's action for each observation, in env units, without any search.

        Why public: what the planner adds is measured against what its prior does alone on the
        same goals (`benchmarks/mpc_prior_probe.py`)."""
        if self.prior is None:
            raise ValueError("this agent has no prior: its preset sets no mpc.prior_trajectories")
        with torch.no_grad():
            unit = self.prior(torch.as_tensor(np.atleast_2d(np.asarray(obs, dtype=np.float32)), device=self.device))
        return self._to_env(unit)

    def _previous_plans(self, state: torch.Tensor | None, episode_start: np.ndarray | None, num_envs: int) -> torch.Tensor:
        """The plans carried from the last step, zeros where an episode starts (or none was carried)."""
        plans = self.initial_state(num_envs) if state is None else state.clone()
        if episode_start is not None:
            plans[torch.as_tensor(np.atleast_1d(episode_start), dtype=torch.bool, device=self.device)] = 0.0
        return plans

    def _proposals(self, obs: torch.Tensor) -> torch.Tensor:
        """The prior's `prior_trajectories` sequences per env `[envs, k, horizon, action]`: the
        policy stepped through the members' mean prediction from `obs`; every proposal but the
        first has `prior_std` noise on its actions (which the next prediction then reads)."""
        assert self.prior is not None
        k, members = self.mpc.prior_trajectories, self.mpc.ensemble_size
        envs = obs.shape[0]
        state = obs.repeat_interleave(k, dim=0)  # rows: (env, proposal)
        noise_std = torch.full((k, 1), self.mpc.prior_std, device=self.device)
        noise_std[0] = 0.0
        noise_std = noise_std.repeat(envs, 1)
        steps = []
        for _ in range(self.mpc.horizon):
            noise = torch.randn((envs * k, self.action_size), generator=self.plan_generator, device=self.device)
            action = (self.prior(state) + noise_std * noise).clamp(-1.0, 1.0)
            steps.append(action)
            rows = (state[None].expand(members, -1, -1), self._scale(action)[None].expand(members, -1, -1))
            state = self.model.mean_prediction(*rows)[0].mean(dim=0)
        return torch.stack(steps, dim=1).reshape(envs, k, self.mpc.horizon, self.action_size)

    def score(self, obs: torch.Tensor, candidates: torch.Tensor) -> torch.Tensor:
        """Predicted return `[envs, n]` of candidate sequences `[envs, n, horizon, action]` (in
        [-1, 1]) from `obs` `[envs, obs]`: `particles` rollouts each, particle p through member
        p mod members for the whole horizon (TS-inf), rewards discounted and summed, plus the
        discounted terminal value of each particle's last state (`terminal_value`); the
        particles' mean, plus `optimism` times their std.

        Why public: what the planner prefers is the question when a run stalls; a probe scores
        its own sequences (a scripted push, holding still) with exactly this
        (`benchmarks/mpc_push_probe.py`)."""
        members, per_member = self.mpc.ensemble_size, self.mpc.particles // self.mpc.ensemble_size
        envs, n, horizon, _ = candidates.shape
        env_actions = self._scale(candidates)
        # rows of one member: (env, candidate, particle) flattened; every member gets them all
        actions = env_actions[:, :, None].expand(-1, -1, per_member, -1, -1).reshape(envs * n * per_member, horizon, -1)
        state = obs[:, None, None].expand(-1, n, per_member, -1).reshape(1, envs * n * per_member, -1).expand(members, -1, -1)
        total = torch.zeros((members, envs * n * per_member), device=self.device)
        for t in range(horizon):
            state, reward = self.model.sample(state, actions[None, :, t].expand(members, -1, -1), self.plan_generator)
            total += self.mpc.discount**t * reward
        if self.value is not None and self.value_started:
            total += self.mpc.discount**horizon * self.value(state)
        returns = total.reshape(members, envs, n, per_member).permute(1, 2, 0, 3).reshape(envs, n, members * per_member)
        if self.mpc.optimism:  # optimism in the face of the members' disagreement (MPCSpec.optimism)
            return returns.mean(dim=-1) + self.mpc.optimism * returns.std(dim=-1)
        return returns.mean(dim=-1)

    def _scale(self, unit: torch.Tensor) -> torch.Tensor:
        """Actions planned in [-1, 1] onto the env's box."""
        return self.low + (unit + 1.0) * 0.5 * (self.high - self.low)

    def to_unit(self, env_actions: torch.Tensor) -> torch.Tensor:
        """Actions in the env's box onto the planner's [-1, 1] (`_scale`'s inverse, clamped): how
        the demos' and the buffer's actions reach what learns in the planner's units."""
        return (2.0 * (env_actions - self.low) / (self.high - self.low) - 1.0).clamp(-1.0, 1.0)

    def _to_env(self, unit: torch.Tensor) -> np.ndarray:
        return self._scale(unit.to(self.device)).cpu().numpy().astype(self.action_space.dtype)

    # ------------------------------------------------------------------------------- training

    def collect(self, envs: VectorEnv, on_step: OnStep | None = None) -> None:
        """`steps_per_update` env steps (all envs together) into the buffer (module doc, 1.)."""
        check_same_step_autoreset(envs)
        if self._obs is None:  # gymnasium seeds env i with seed + i; later resets move past them
            self._obs, infos = envs.reset(seed=self.seed + self._env_resets * envs.num_envs)
            self._env_resets += 1
            self._plans = self.initial_state(envs.num_envs)
            self._follow_stage(infos, np.ones(envs.num_envs, dtype=bool))
        obs, plans = self._obs, self._plans
        assert plans is not None
        for _ in range(math.ceil(self.mpc.steps_per_update / envs.num_envs)):
            if not self.data_given and self.global_step < self.mpc.random_steps:
                unit = torch.rand((envs.num_envs, self.action_size), generator=self.generator) * 2 - 1
                actions = self._to_env(unit)
            else:
                actions, plans = self.act(obs, plans)
            next_obs, reward, terminated, truncated, infos = envs.step(actions)
            self.global_step += envs.num_envs
            if on_step is not None:
                on_step(reward, terminated, truncated, infos)
            ended = terminated | truncated
            landed = next_obs.copy()  # where each transition really ended (SAME_STEP autoreset)
            for i in np.flatnonzero(ended):
                landed[i] = infos["final_obs"][i]
            self.buffer.add(obs, actions, reward, landed, self._stage_tags(infos, ended))
            self._follow_stage(infos, ended)  # the episodes that started in this step
            plans[torch.as_tensor(ended, device=self.device)] = 0.0
            obs = next_obs
        self._obs, self._plans = obs, plans

    def _tag(self, stage: str) -> int:
        if stage not in self.stage_names:
            self.stage_names.append(stage)
        return self.stage_names.index(stage)

    def _stage_tags(self, infos: dict, ended: np.ndarray) -> np.ndarray:
        """Each env's transition's stage: that of the episode it belongs to (`final_info`'s where
        the episode ended, since the env has already reset into its next one); UNTAGGED from an
        env that names none (a plain gymnasium env)."""
        tags = np.full(len(ended), UNTAGGED, dtype=np.int16)
        for i, over in enumerate(ended):
            stage = _stage_of(infos.get("final_info", {}) if over else infos, i)
            if stage is not None:
                tags[i] = self._tag(stage)
        return tags

    def _follow_stage(self, infos: dict, started: np.ndarray) -> None:
        """The stage being trained is that of the latest episode started that is not a replay of
        an earlier stage: after a promotion every worker's next episode is the new stage's."""
        for i in np.flatnonzero(started):
            stage = _stage_of(infos, i)
            if stage is not None and not bool(infos.get("replay", np.zeros(i + 1, bool))[i]):
                self.stage = self._tag(stage)

    def _new_value(self) -> None:
        """The terminal value and its optimizer(s) from new weights (drawn from `generator`): at
        the start, and at each fresh refit. With `value_policy`, its policy is the one that
        proposes (`prior`), so a refit renews the proposals too."""
        obs_size = self.observation_space.shape[0]
        if self.mpc.value_policy:
            self.value = PolicyValue(obs_size, self.action_size, self.mpc.hidden_sizes, self.mpc.discount, self.mpc.value_tau,
                                     self.generator, self.mpc.value_policy_alpha, self.mpc.value_bound).to(self.device)
            self.value_optimizer, self.policy_optimizer = self.value.optimizers()
            if self.mpc.prior_trajectories:
                self.prior = self.value.policy
            return
        self.value = TerminalValue(obs_size, self.mpc.hidden_sizes, self.mpc.discount, self.mpc.value_tau, self.generator,
                                   self.mpc.value_ensemble, self.mpc.value_pessimism, self.mpc.value_bound).to(self.device)
        self.value_optimizer = torch.optim.Adam(self.value.net.parameters(), lr=self.mpc.learning_rate)

    def update(self) -> dict[str, float]:
        """Fit the model on the buffer (module doc, 2.); its losses as metrics."""
        if self.buffer.size == 0:
            return {}
        with torch_threads(update_threads(self.spec.runtime)):
            return self._fit()

    def _fit(self) -> dict[str, float]:
        mpc, model, obs_size = self.mpc, self.model, self.observation_space.shape[0]
        inputs, targets = (t.to(self.device) for t in self.buffer.inputs_and_targets())
        # The motion is the same whatever the stage; the reward is not: after a promotion the rows
        # collected on the earlier stage carry its reward on the same states. The reward and the
        # value learn from the stage being trained's rows alone (all rows until one has any).
        rows = self.buffer.rows_of(self.stage)
        rows = (rows if len(rows) else torch.arange(self.buffer.size)).to(self.device)
        every_row = len(rows) == self.buffer.size  # one stage: the reward reads the motion's batch
        model.fit_normalization(inputs, targets, None if every_row else targets[rows, -1])
        batch = min(mpc.batch_size, self.buffer.size)
        total = 0.0
        for _ in range(mpc.model_updates):
            # bootstrap: each member draws its own batch with replacement (and one for the reward)
            idx = torch.randint(self.buffer.size, (mpc.ensemble_size, batch), generator=self.generator).to(self.device)
            reward_batch = None
            if not every_row:
                reward_idx = rows[torch.randint(len(rows), (mpc.ensemble_size, batch), generator=self.generator).to(self.device)]
                reward_batch = (inputs[reward_idx], targets[reward_idx, -1])
            total += model.fit_batch(self.optimizer, inputs[idx], targets[idx], reward_batch)
        self.num_updates += 1
        with torch.no_grad():  # the fit's error on a sample of the stage's data, in the data's units
            sample = rows[torch.randint(len(rows), (min(2048, len(rows)),), generator=self.generator).to(self.device)]
            x, y = inputs[sample], targets[sample]
            next_obs, reward = model.mean_prediction(x[None, :, :obs_size].expand(mpc.ensemble_size, -1, -1),
                                                     x[None, :, obs_size:].expand(mpc.ensemble_size, -1, -1))
            obs_error = ((next_obs - x[None, :, :obs_size]) - y[None, :, :obs_size]) ** 2
            reward_error = (reward - y[None, :, obs_size]) ** 2
        metrics = {"model_nll": total / mpc.model_updates, "model_obs_mse": obs_error.mean().item(),
                   "model_reward_mse": reward_error.mean().item(), "buffer_size": float(self.buffer.size),
                   "reward_rows": float(len(rows))}
        if self.value is not None and self.global_step >= mpc.value_start:  # on the device already, in the fit's data
            self.value_started = True
            stage = slice(None) if every_row else rows  # a slice copies nothing
            rewards = targets[stage, obs_size]
            if mpc.value_relabel and not every_row:  # every row, the earlier stages' with this one's reward
                stage, rewards = slice(None), self._stage_rewards(inputs, targets[:, obs_size], rows)
                metrics["value_relabelled_rows"] = float(self.buffer.size - len(rows))
            landed = self.buffer.next_obs[: self.buffer.size].to(self.device)[stage]
            updates = mpc.value_updates or mpc.model_updates  # `mpc.value_updates`: TD-MPC2's one step per env step
            # Fresh refit (`mpc.value_refit_every`; Nikishin et al. 2022's reset against the primacy
            # bias): at the first fit and at each multiple of the period passed, V starts from new
            # weights and fits the whole stage's data at once; the fits between go on from it.
            if mpc.value_refit_every and self.global_step // mpc.value_refit_every >= self.value_refits:
                self._new_value()
                self.value_refits = self.global_step // mpc.value_refit_every + 1
                updates = mpc.value_refit_updates
                metrics["value_refit"] = 1.0
            obs, mean, std = inputs[stage, :obs_size], model.in_mean[:obs_size], model.in_std[:obs_size]
            if isinstance(self.value, PolicyValue):  # Q and pi also read the actions taken, in the planner's units
                optimizers = (self.value_optimizer, self.policy_optimizer)
                metrics |= self.value.fit(obs, self.to_unit(inputs[stage, obs_size:]), rewards, landed, mean, std, optimizers,
                                          updates, batch, self.generator)
            else:
                assert self.value is not None
                metrics |= self.value.fit(obs, rewards, landed, mean, std, self.value_optimizer, updates, batch, self.generator)
        return metrics

    def _stage_rewards(self, inputs: torch.Tensor, stored: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        """Every filled row's reward as the stage being trained's (`mpc.value_relabel`): `stored`
        on its own `rows`, elsewhere what the model's reward network (its members' mean, fitted on
        those rows just before) predicts for the row's observation and action. In chunks, so a
        large buffer does not hold every member's activations at once."""
        obs_size, members = self.observation_space.shape[0], self.mpc.ensemble_size
        rewards = stored.clone()
        others = torch.ones(len(stored), dtype=torch.bool, device=stored.device)
        others[rows] = False
        with torch.no_grad():
            for chunk in torch.split(torch.nonzero(others).flatten(), RELABEL_CHUNK):
                x = inputs[chunk][None].expand(members, -1, -1)
                rewards[chunk] = self.model.mean_prediction(x[..., :obs_size], x[..., obs_size:])[1].mean(dim=0)
        return rewards

    def add_demonstrations(self, observations: np.ndarray, actions: np.ndarray, rewards: np.ndarray,
                           episode_starts: np.ndarray, stage: str) -> int:
        """Seed the model's data with scripted episodes of `stage` (the warm start of `algo:
        mpc`): every step with a successor in its episode becomes a transition. Returns how many.
        Their reward is `stage`'s: it trains the reward once that stage is being trained."""
        starts = np.asarray(episode_starts, dtype=bool)
        keep = np.flatnonzero(~np.append(starts[1:], True))  # not an episode's last step
        tag = self._tag(stage)
        self.buffer.add(observations[keep], actions[keep], rewards[keep], observations[keep + 1], np.full(len(keep), tag))
        self.data_given = True
        if self.stage is None:  # fitted before the first collect: on the demos' stage
            self.stage = tag
        return len(keep)

    def fit_prior(self, observations: np.ndarray, actions: np.ndarray, epochs: int, batch_size: int,
                  learning_rate: float) -> dict[str, float]:
        """Clone the demos' actions (env units, mapped onto the planner's [-1, 1]) into the prior
        (`prior.py`); its fit's error as a metric. Only with `prior_trajectories`."""
        assert self.prior is not None
        obs = torch.as_tensor(np.asarray(observations), dtype=torch.float32, device=self.device)
        env_actions = torch.as_tensor(np.asarray(actions), dtype=torch.float32, device=self.device)
        unit = self.to_unit(env_actions)
        with torch_threads(update_threads(self.spec.runtime)):
            return self.prior.fit(obs, unit, epochs, batch_size, learning_rate, self.generator)

    def set_progress(self, fraction: float) -> None:
        """Nothing is scheduled over the budget (PPO anneals its learning rate here)."""

    # ------------------------------------------------------------------------------ checkpoint

    def state_dict(self) -> dict:
        """Model, optimizer, data, RNG and counters: tensors and plain values only (loads with
        `torch.load(weights_only=True)`). The buffer is saved whole, each observation once
        (`TransitionBuffer.state_dict`): a resumed run refits on it."""
        state = {"model": self.model.state_dict(), "optimizer": self.optimizer.state_dict(),
                 "buffer": self.buffer.state_dict(), "generator": self.generator.get_state(), "seed": self.seed,
                 "global_step": self.global_step, "num_updates": self.num_updates, "env_resets": self._env_resets,
                 "data_given": self.data_given, "stage_names": list(self.stage_names), "stage": self.stage,
                 "value_refits": self.value_refits, "value_started": self.value_started}
        if self.plan_generator is not self.generator:
            state |= {"plan_generator": self.plan_generator.get_state(), "plan_device": self.device.type}
        if self.value is not None:
            state |= {"value": self.value.state_dict(), "value_optimizer": self.value_optimizer.state_dict()}
        if self.mpc.value_policy:  # its policy (the prior, with proposals) is saved with the value
            state["policy_optimizer"] = self.policy_optimizer.state_dict()
        elif self.prior is not None:
            state["prior"] = self.prior.state_dict()
        return state

    def load_weights(self, state: dict) -> None:
        """Start from another run's learnt model (`init_from`): the ensemble (with its input and
        target statistics), the terminal value where both have one, and the transitions the model
        was fitted on, since each update refits on the buffer and would otherwise forget what the
        data taught. The optimizer, RNG and counters stay this run's. `WeightsMismatch` if they
        do not fit."""
        require(state, ("model", "buffer"), "MPC")
        load_matching(self.model, state["model"], "dynamics model")
        if (self.value is None) != ("value" not in state):
            have = "has no terminal value" if self.value is not None else "has a terminal value this agent lacks"
            raise WeightsMismatch(f"it {have} (mpc.terminal_value differs)")
        if self.value is not None:
            load_matching(self.value, state["value"], "terminal value")
        rows = state["buffer"]["rewards"]
        if len(rows) > self.buffer.capacity:
            raise WeightsMismatch(f"its {len(rows):,} transitions exceed this agent's mpc.buffer_size ({self.buffer.capacity:,})")
        self.buffer.load_state_dict(state["buffer"])
        # the other run's tags, onto this agent's names (a stage it trains too shares its rows)
        names = torch.as_tensor([self._tag(n) for n in state.get("stage_names", [])] + [UNTAGGED], dtype=torch.int16)  # [-1]: untagged stays so
        tags = self.buffer.stages[: len(rows)]
        tags.copy_(names[tags.long()])
        self.data_given = True
        if len(rows) < self.buffer.capacity:  # a larger buffer appends after the loaded rows
            self.buffer.cursor = len(rows)

    def load_state_dict(self, state: dict) -> None:
        self.model.load_state_dict(state["model"])
        self.optimizer.load_state_dict(state["optimizer"])
        if self.value is not None:
            self.value.load_state_dict(state["value"])
            self.value_optimizer.load_state_dict(state["value_optimizer"])
        if self.mpc.value_policy:
            self.policy_optimizer.load_state_dict(state["policy_optimizer"])
        elif self.prior is not None:
            self.prior.load_state_dict(state["prior"])
        self.buffer.load_state_dict(state["buffer"])
        self.generator.set_state(state["generator"])
        if self.plan_generator is not self.generator:
            # a run moved between devices cannot carry the planner's stream over: start a new one
            if state.get("plan_device") == self.device.type:
                self.plan_generator.set_state(state["plan_generator"])
            else:
                self.plan_generator.manual_seed(state["seed"] + state["global_step"])
        self.seed, self.global_step, self.num_updates = state["seed"], state["global_step"], state["num_updates"]
        self._env_resets = state["env_resets"]
        # checkpoints from before `data_given`: their random phase ended at the first fit
        self.data_given = state.get("data_given", self.num_updates > 0)
        # checkpoints from before the stage tags: every row untagged, no stage named
        self.stage_names, self.stage = list(state.get("stage_names", [])), state.get("stage")
        self.value_refits = state.get("value_refits", 0)  # from before the refits: none done
        self.value_started = state.get("value_started", True)  # from before `value_start`: live from the first fit
        self._obs = None  # the envs are not the agent's: the next collect() resets them
