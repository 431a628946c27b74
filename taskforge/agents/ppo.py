"""PPO (Schulman et al., 2017) for continuous actions, after CleanRL's `ppo_continuous_action.py`
and, for the recurrent policy, `ppo_atari_lstm.py`.

"detail #k" comments name the implementation details of Huang et al. (2022), "The 37
Implementation Details of Proximal Policy Optimization": plain numbers are the 13 core details,
"continuous detail #k" and "LSTM detail #k" the sections of those names.

Differences from CleanRL, all deliberate:
* time-limit truncation is bootstrapped from V(final observation) instead of treated as
  terminal (see `gae.py`); this needs SAME_STEP autoreset (see `runtime.make_vector_env`);
* the caller owns the step budget, so learning-rate annealing follows `set_progress()`;
* observation/reward normalisation live in the agent, not in env wrappers, so their statistics
  are saved with the networks and frozen for evaluation;
* an optional asymmetric critic reads `concat(obs, info["privileged"])`;
* an optional behaviour-cloning term on demonstrations, with a decaying weight (DAPG,
  Rajeswaran et al. 2018; see `set_demo_regularizer` and `agents/bc.py` for the pretraining).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import gymnasium
import numpy as np
import torch
from gymnasium.vector import VectorEnv
from torch import nn

from taskforge.agents.normalization import ObservationNormalizer, RewardScaler
from taskforge.agents.policies import ActorCritic, RecurrentState
from taskforge.agents.runtime import check_same_step_autoreset, torch_threads, update_threads
from taskforge.agents.sequences import DemoRows, columns_per_batch, demo_rows
from taskforge.agents.storage import Minibatch, RolloutBuffer
from taskforge.agents.weights import WeightsMismatch, load_matching, require
from taskforge.spec.agent import AgentSpec, PPOSpec

OnStep = Callable[[np.ndarray, np.ndarray, np.ndarray, dict], None]


@dataclass(frozen=True)
class PPOLoss:
    """The loss of one minibatch (`total` carries the graph) and its detached parts."""

    total: torch.Tensor
    policy_loss: float
    value_loss: float
    entropy: float
    approx_kl: float
    old_approx_kl: float
    clipfrac: float


def ppo_loss(policy: ActorCritic, mb: Minibatch, ppo: PPOSpec, generator: torch.Generator, train_actor: bool = True) -> PPOLoss:
    """PPO's objective on one minibatch, as in CleanRL's inner loop. With `train_actor` False
    only the value loss carries a gradient (critic warm-up; see `PPOAgent.warm_up_critic`)."""
    newlogprob, entropy, newvalue = policy.evaluate(
        mb.obs, mb.critic_obs, mb.actions, mb.state, mb.episode_starts, generator
    )
    logratio = newlogprob - mb.logprobs
    ratio = logratio.exp()

    with torch.no_grad():  # debug variables (detail #12); approx_kl is the k3 estimator of KL(old, new)
        old_approx_kl = (-logratio).mean()
        approx_kl = ((ratio - 1.0) - logratio).mean()
        clipfrac = ((ratio - 1.0).abs() > ppo.clip_coef).float().mean()

    advantages = mb.advantages
    if ppo.norm_adv:  # advantage normalisation, per minibatch (detail #7)
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)

    # clipped surrogate objective (detail #8)
    pg_loss1 = -advantages * ratio
    pg_loss2 = -advantages * torch.clamp(ratio, 1.0 - ppo.clip_coef, 1.0 + ppo.clip_coef)
    pg_loss = torch.max(pg_loss1, pg_loss2).mean()

    if ppo.clip_vloss:  # clipped value loss (detail #9)
        v_loss_unclipped = (newvalue - mb.returns) ** 2
        v_clipped = mb.values + torch.clamp(newvalue - mb.values, -ppo.clip_coef, ppo.clip_coef)
        v_loss_clipped = (v_clipped - mb.returns) ** 2
        v_loss = 0.5 * torch.max(v_loss_unclipped, v_loss_clipped).mean()
    else:
        v_loss = 0.5 * ((newvalue - mb.returns) ** 2).mean()

    entropy_loss = entropy.mean()
    if train_actor:  # overall loss with entropy bonus (detail #10)
        loss = pg_loss - ppo.ent_coef * entropy_loss + ppo.vf_coef * v_loss
    else:  # critic warm-up: the actor gets no gradient
        loss = ppo.vf_coef * v_loss
    return PPOLoss(
        total=loss,
        policy_loss=pg_loss.item(),
        value_loss=v_loss.item(),
        entropy=entropy_loss.item(),
        approx_kl=approx_kl.item(),
        old_approx_kl=old_approx_kl.item(),
        clipfrac=clipfrac.item(),
    )


@dataclass(frozen=True)
class DemoRegularizer:
    """Demonstrations for the BC term of the PPO loss: raw (unnormalised) observations, the demo
    actions as raw Gaussian samples, and the weight schedule `weight * decay**k`."""

    observations: np.ndarray
    raw_actions: torch.Tensor
    weight: float
    decay: float
    rows: DemoRows
    """The demo steps as the policy reads them (single steps, or episodes for a recurrent one)."""
    columns: int
    """Rows drawn per minibatch: about `batch_size` demo steps."""

    def weight_at(self, update: int) -> float:
        return self.weight * self.decay**update


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> float:
    """`1 - Var[returns - values] / Var[returns]`: 1 is a perfect critic, <= 0 no better than a
    constant (NaN when the returns do not vary)."""
    var_returns = returns.var()
    return float("nan") if var_returns == 0 else (1.0 - (returns - values).var() / var_returns).item()


class PPOAgent:
    """A PPO learner that a trainer drives with `collect()` / `update()` / `set_progress()`.

    It never sees which simulator it trains on: any gymnasium `VectorEnv` with a flat `Box`
    observation and action space, built with SAME_STEP autoreset (`make_vector_env`). With
    `spec.asymmetric_critic`, every env must put a float vector of length `privileged_dim` in
    `info["privileged"]` on reset and on every step; the critic reads `concat(obs, privileged)`
    and the actor `obs` only. With a symmetric spec, `privileged_dim` is ignored.

    Seeding: network init, action sampling and minibatch shuffles draw from generators seeded
    by `seed` (never torch's global RNG), and the first `collect()` resets the envs with `seed`,
    so the same seed gives the same run (at a fixed `torch.set_num_threads`).
    """

    def __init__(
        self,
        spec: AgentSpec,
        obs_space: gymnasium.spaces.Box,
        action_space: gymnasium.spaces.Box,
        privileged_dim: int = 0,
        seed: int = 0,
    ) -> None:
        for name, space in (("observation", obs_space), ("action", action_space)):
            if not isinstance(space, gymnasium.spaces.Box) or len(space.shape) != 1:
                raise ValueError(f"PPOAgent needs a flat Box {name} space, got {space}")
        if spec.asymmetric_critic and privileged_dim < 1:
            raise ValueError(
                "asymmetric_critic is set, so PPOAgent needs privileged_dim >= 1 (the length of info['privileged'])"
            )
        ppo = spec.ppo  # AgentSpec already checks that an LSTM has at least one env per minibatch
        self.spec = spec
        self.seed = seed
        self.action_space = action_space
        self.privileged_dim = privileged_dim if spec.asymmetric_critic else 0
        obs_dim = obs_space.shape[0]
        critic_dim = obs_dim + self.privileged_dim

        with torch.random.fork_rng(devices=[]):  # seeded init without disturbing the caller's global RNG
            torch.manual_seed(seed)
            self.policy = ActorCritic(spec.policy, obs_dim, critic_dim, action_space)
        # Adam with eps 1e-5 (detail #3); foreach batches the per-tensor kernels, which dominate for small nets on CPU
        self.optimizer = torch.optim.Adam(self.policy.parameters(), lr=ppo.learning_rate, eps=1e-5, foreach=True)
        self.generator = torch.Generator().manual_seed(seed)
        self.obs_normalizer = ObservationNormalizer(obs_dim, ppo.norm_obs)
        has_privileged = self.privileged_dim > 0
        self.privileged_normalizer = ObservationNormalizer(self.privileged_dim, ppo.norm_obs and has_privileged)
        self.reward_scaler = RewardScaler(ppo.num_envs, ppo.gamma, ppo.norm_reward)
        self.buffer = RolloutBuffer(
            ppo.rollout_steps, ppo.num_envs, obs_dim, critic_dim, action_space.shape[0], ppo.bptt_length
        )

        self.global_step = 0
        self.num_updates = 0
        self.progress = 0.0
        self._env_resets = 0
        self._rollout_ready = False
        self._all_envs = np.arange(ppo.num_envs)
        # Carried between collect() calls: last (normalised) obs, whether it starts an episode, recurrent state.
        self._obs: torch.Tensor | None = None
        self._critic_obs: torch.Tensor | None = None
        self._episode_starts: torch.Tensor | None = None
        self._state: RecurrentState | None = None
        self.demo_regularizer: DemoRegularizer | None = None
        self.critic_warmup_until = 0
        """Updates before this index train the critic only (`warm_up_critic`)."""
        self.observation_stats_frozen = False
        """Rollouts no longer update the observation normaliser (`freeze_observation_statistics`)."""

    def set_demo_regularizer(
        self, observations: np.ndarray, actions: np.ndarray, weight: float, decay: float, batch_size: int | None = None,
        episode_starts: np.ndarray | None = None,
    ) -> None:
        """Add `weight * decay**k * -log pi(a_demo | s_demo)` to the loss of every minibatch of
        PPO update k (counting from 0 with `num_updates`), averaged over about `batch_size` demo
        steps drawn afresh per minibatch (default: PPO's minibatch size). DAPG's behaviour-cloning
        term (Rajeswaran et al., 2018) with their schedule, without their advantage weighting:
        it keeps the policy near the demonstrations early and fades as PPO takes over.
        `actions` are env actions; observations are normalised with the current statistics at
        every update. A recurrent policy reads whole demo episodes (`episode_starts`), each from
        a fresh state, as it was cloned (`agents/sequences.py`)."""
        if self.policy.recurrent and episode_starts is None:
            raise ValueError("a recurrent policy's demonstration term runs whole episodes: pass the demos' episode_starts")
        ppo = self.spec.ppo
        batch = batch_size or ppo.num_envs * ppo.rollout_steps // ppo.num_minibatches
        raw = self.policy.actions.from_env(torch.as_tensor(np.asarray(actions, dtype=np.float32)))
        starts = np.ones(len(raw), dtype=bool) if episode_starts is None else episode_starts
        rows = demo_rows(starts, self.policy.recurrent)
        self.demo_regularizer = DemoRegularizer(np.asarray(observations, dtype=np.float32), raw, weight, decay,
                                                rows, min(columns_per_batch(rows, batch), rows.width))

    def warm_up_critic(self, updates: int) -> None:
        """Train only the critic for the next `updates` PPO updates. After a warm start the actor
        is good and the critic has seen only the demonstrations: advantages from that critic on
        the policy's own rollouts are mostly noise, and following them undoes the pretraining.
        Counted from `num_updates`, saved in the checkpoint."""
        self.critic_warmup_until = self.num_updates + updates

    def freeze_observation_statistics(self) -> None:
        """Stop updating the observation normaliser from rollouts. A pretrained actor is a function
        of observations normalised with the demos' statistics; if rollouts of other stages (a goal
        on the table, a puck never lifted) keep moving the mean and std, the same raw observation
        reaches the network as another input and the pretrained behaviour drifts away although no
        weight changed (measured: held-out success 0.90 -> 0.38 within 12k steps of critic-only
        updates). Saved in the checkpoint."""
        self.observation_stats_frozen = True

    # ----------------------------------------------------------------------------------- rollout

    def collect(self, envs: VectorEnv, on_step: OnStep | None = None) -> None:
        """Run `spec.ppo.rollout_steps` steps in every env into the rollout buffer.

        After each vector step, `on_step(rewards, terminated, truncated, infos)` gets the env's raw
        outputs (unscaled rewards; `infos["final_info"]` for episodes that ended) so the caller can
        log episodes or feed a curriculum. The last observation, episode-start flags and recurrent
        state carry over to the next call; the first call (and the first after `reset_envs()`)
        resets the envs with a seed derived from the agent's.
        """
        check_same_step_autoreset(envs)
        ppo = self.spec.ppo
        if envs.num_envs != ppo.num_envs:
            raise ValueError(f"the vector env has {envs.num_envs} envs but spec.ppo.num_envs is {ppo.num_envs}")
        if self._obs is None:
            self._reset(envs)
        obs, critic_obs, episode_starts, state = self._obs, self._critic_obs, self._episode_starts, self._state

        for t in range(ppo.rollout_steps):
            self.buffer.record_state(t, state)  # the update re-runs each BPTT chunk from here (LSTM detail #5)
            with torch.no_grad():
                raw_action, logprob, value, state = self.policy.step(
                    obs[None], critic_obs[None], state, episode_starts[None], self.generator
                )
            # the env gets the clipped/squashed action, the buffer keeps the raw sample (continuous detail #5)
            env_action = self._to_env(raw_action[0])
            next_obs, reward, terminated, truncated, infos = envs.step(env_action)
            self.global_step += envs.num_envs
            if on_step is not None:
                on_step(reward, terminated, truncated, infos)

            self.buffer.store(
                t,
                obs=obs,
                critic_obs=critic_obs,
                episode_starts=episode_starts,
                actions=raw_action[0],
                logprobs=logprob[0],
                values=value[0],
                rewards=self.reward_scaler(reward, terminated, truncated),  # continuous details #8, #9
                terminated=torch.as_tensor(terminated),
                truncated=torch.as_tensor(truncated),
                final_values=self._truncation_values(infos, truncated & ~terminated, state),
            )
            obs, critic_obs = self._observe(next_obs, self._privileged(infos, self._all_envs), update=True)
            episode_starts = torch.as_tensor(terminated | truncated)

        with torch.no_grad():  # bootstrap the unfinished episodes from the observation after the rollout
            last_values, _ = self.policy.value(critic_obs[None], state, episode_starts[None])
        self.buffer.compute_advantages(last_values[0], ppo.gamma, ppo.gae_lambda)
        self._obs, self._critic_obs, self._episode_starts, self._state = obs, critic_obs, episode_starts, state
        self._rollout_ready = True

    def _reset(self, envs: VectorEnv) -> None:
        # gymnasium seeds env i with seed + i; later resets move past the seeds already used
        obs, infos = envs.reset(seed=self.seed + self._env_resets * envs.num_envs)
        self._env_resets += 1
        self.reward_scaler.reset()
        self._obs, self._critic_obs = self._observe(obs, self._privileged(infos, self._all_envs), update=True)
        self._episode_starts = torch.ones(envs.num_envs, dtype=torch.bool)
        self._state = self.policy.initial_state(envs.num_envs)

    def _observe(self, obs: np.ndarray, privileged: np.ndarray, update: bool) -> tuple[torch.Tensor, torch.Tensor]:
        """Normalised actor input and critic input (`concat(obs, privileged)`)."""
        update = update and not self.observation_stats_frozen
        obs_n = self.obs_normalizer(obs, update)  # observation normalisation + clipping (continuous #6, #7)
        return obs_n, torch.cat([obs_n, self.privileged_normalizer(privileged, update)], dim=-1)

    def _privileged(self, infos: dict, rows: np.ndarray) -> np.ndarray:
        """`infos["privileged"]` of the envs `rows`, `[len(rows), privileged_dim]` (width 0 for a
        symmetric critic)."""
        if self.privileged_dim == 0:
            return np.zeros((len(rows), 0), dtype=np.float32)
        if "privileged" not in infos or not infos["_privileged"][rows].all():
            raise KeyError("asymmetric_critic: every env must put info['privileged'] in its reset and step infos")
        privileged = np.asarray(infos["privileged"][rows], dtype=np.float32)
        if privileged.shape[1:] != (self.privileged_dim,):
            raise ValueError(f"info['privileged'] has shape {privileged.shape[1:]}, expected ({self.privileged_dim},)")
        return privileged

    def _truncation_values(
        self, infos: dict, truncated: np.ndarray, state: RecurrentState | None
    ) -> torch.Tensor:
        """V(final observation) of the envs whose episode was truncated at this step, 0 elsewhere.

        Under SAME_STEP autoreset the step already returned the next episode's first observation;
        the truncated episode's last one is in `infos["final_obs"]` (its privileged vector in
        `infos["final_info"]`). The final observation is normalised with frozen statistics and
        fed to the critic with the state reached after this step, not reset.
        """
        final_values = torch.zeros(len(truncated))
        if not truncated.any():
            return final_values
        idx = np.flatnonzero(truncated)
        final_obs = np.stack(infos["final_obs"][idx])
        final_privileged = self._privileged(infos["final_info"], idx)
        _, critic_obs = self._observe(final_obs, final_privileged, update=False)
        env_idx = torch.as_tensor(idx)
        with torch.no_grad():
            values, _ = self.policy.value(
                critic_obs[None],
                None if state is None else state.select(env_idx),
                torch.zeros((1, len(idx)), dtype=torch.bool),
            )
        final_values[env_idx] = values[0]
        return final_values

    def _to_env(self, raw: torch.Tensor) -> np.ndarray:
        return self.policy.actions.to_env(raw).numpy().astype(self.action_space.dtype)

    # ------------------------------------------------------------------------------------ update

    def update(self) -> dict[str, float]:
        """PPO epochs over the last rollout; returns the mean of each loss statistic over the
        minibatches run, plus `explained_variance`, `learning_rate`, `epochs` and
        `skipped_minibatches` (those whose loss or gradient was not finite: not applied)."""
        if not self._rollout_ready:
            raise RuntimeError("update() needs a fresh rollout: call collect() first")
        with torch_threads(update_threads(self.spec.runtime)):  # the env workers idle meanwhile
            return self._update()

    def _update(self) -> dict[str, float]:
        ppo = self.spec.ppo
        totals: dict[str, float] = {}
        minibatches_run = skipped = 0
        epochs = 0
        train_actor = self.num_updates >= self.critic_warmup_until  # critic warm-up (see warm_up_critic)
        demos = self.demo_regularizer if train_actor else None
        if demos is not None:
            bc_weight = demos.weight_at(self.num_updates - self.critic_warmup_until)  # decays from the first actor update
            demo_obs = self.obs_normalizer(demos.observations, update=False)
        for epochs in range(1, ppo.update_epochs + 1):  # noqa: B007 (read after the loop: epochs run)
            for mb in self.buffer.minibatches(ppo.num_minibatches, self.generator, self.policy.recurrent):
                loss = ppo_loss(self.policy, mb, ppo, self.generator, train_actor)
                total = loss.total
                if demos is not None:  # DAPG's decaying behaviour-cloning term (see set_demo_regularizer)
                    rows = demos.rows.take(torch.randint(demos.rows.width, (demos.columns,), generator=self.generator))
                    dist, _ = self.policy.distribution(demo_obs[rows.index], self.policy.initial_state(rows.width), rows.starts)
                    bc_loss = -self.policy.actions.log_prob(dist, demos.raw_actions[rows.index])[rows.mask].mean()
                    total = total + bc_weight * bc_loss
                    totals["bc_loss"] = totals.get("bc_loss", 0.0) + bc_loss.item()
                self.optimizer.zero_grad()
                total.backward()
                # global gradient clipping (detail #11)
                grad_norm = nn.utils.clip_grad_norm_(self.policy.parameters(), ppo.max_grad_norm)
                if not (torch.isfinite(total) and torch.isfinite(grad_norm)):
                    # a non-finite loss or gradient would put NaN into every weight: skip it, count it
                    skipped += 1
                    continue
                self.optimizer.step()
                for name in ("policy_loss", "value_loss", "entropy", "approx_kl", "old_approx_kl", "clipfrac"):
                    totals[name] = totals.get(name, 0.0) + getattr(loss, name)
                minibatches_run += 1
            if ppo.target_kl is not None and loss.approx_kl > ppo.target_kl:  # early stop on KL, per epoch (as CleanRL)
                break

        self.num_updates += 1
        self._rollout_ready = False
        metrics = {name: total / max(minibatches_run, 1) for name, total in totals.items()}
        metrics["skipped_minibatches"] = float(skipped)
        metrics["explained_variance"] = explained_variance(self.buffer.values, self.buffer.returns)
        metrics["learning_rate"] = self.optimizer.param_groups[0]["lr"]
        metrics["epochs"] = float(epochs)
        if demos is not None:
            metrics["bc_weight"] = bc_weight
        metrics["actor_trained"] = float(train_actor)
        return metrics

    def set_progress(self, fraction: float) -> None:
        """Tell the agent how much of the training budget is spent (0..1); with `anneal_lr` the
        learning rate decays linearly to 0 at 1 (detail #4). The caller owns the budget, which
        a curriculum may stretch, so the agent cannot compute this itself."""
        self.progress = min(max(float(fraction), 0.0), 1.0)
        ppo = self.spec.ppo
        lr = ppo.learning_rate * (1.0 - self.progress) if ppo.anneal_lr else ppo.learning_rate
        for group in self.optimizer.param_groups:
            group["lr"] = lr

    # -------------------------------------------------------------------------------- evaluation

    def initial_state(self, num_envs: int) -> RecurrentState | None:
        """Recurrent state for `act()` on `num_envs` envs (None for an MLP policy)."""
        return self.policy.initial_state(num_envs)

    def act(
        self,
        obs: np.ndarray,
        state: RecurrentState | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, RecurrentState | None]:
        """Env-ready actions for a batch `[n, obs_dim]` (or one observation `[obs_dim]`).

        Observations are normalised with frozen statistics. For an LSTM policy pass back the
        returned state each step and `episode_start[i] = True` on the first step of an episode
        in env i (its state is then zeroed); `state=None` starts from `initial_state(n)`.
        """
        obs = np.asarray(obs)
        batch = np.atleast_2d(obs)
        if state is None:
            state = self.policy.initial_state(len(batch))
        starts = (
            torch.zeros(len(batch), dtype=torch.bool)
            if episode_start is None
            else torch.as_tensor(np.atleast_1d(episode_start), dtype=torch.bool)
        )
        with torch.no_grad():
            obs_n = self.obs_normalizer(batch, update=False)
            action, state = self.policy.act(obs_n[None], state, starts[None], deterministic, self.generator)
        env_action = action[0].numpy().astype(self.action_space.dtype)
        return (env_action[0] if obs.ndim == 1 else env_action), state

    def reset_envs(self) -> None:
        """Forget the carried observation and recurrent state, so the next `collect()` resets the
        (rebuilt) envs and the reward scaler's per-episode returns."""
        self._obs = self._critic_obs = self._episode_starts = None
        self._state = None
        self._rollout_ready = False

    # ---------------------------------------------------------------------------- checkpointing

    def state_dict(self) -> dict:
        """Everything needed to resume learning exactly: networks, optimizer, normaliser
        statistics, the seed, the RNG and counters. Only tensors and plain Python values, so it
        loads with `torch.load(weights_only=True)`. The episodes in flight are not saved (the envs
        are not the agent's): after loading, the next `collect()` resets the envs."""
        return {
            "policy": self.policy.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "obs_normalizer": self.obs_normalizer.rms.state_dict(),
            "privileged_normalizer": self.privileged_normalizer.rms.state_dict(),
            "reward_scaler": self.reward_scaler.rms.state_dict(),
            "generator": self.generator.get_state(),
            "seed": self.seed,
            "global_step": self.global_step,
            "num_updates": self.num_updates,
            "progress": self.progress,
            "env_resets": self._env_resets,
            "critic_warmup_until": self.critic_warmup_until,
            "observation_stats_frozen": self.observation_stats_frozen,
        }

    def load_weights(self, state: dict) -> None:
        """Start from another run's learnt policy (`init_from`): its networks and the statistics
        they were trained on (observation and reward normalisers; a network fed other statistics
        sees other inputs). The optimizer, RNG, counters and learning-rate schedule stay this
        run's: the new curriculum is a new run. `WeightsMismatch` if they do not fit."""
        require(state, ("policy", "obs_normalizer", "privileged_normalizer", "reward_scaler"), "PPO or RL²")
        load_matching(self.policy, state["policy"], "policy")
        for name in ("obs_normalizer", "privileged_normalizer", "reward_scaler"):
            try:
                getattr(self, name).rms.load_state_dict(state[name])  # checks the shape before it assigns
            except ValueError as exc:
                raise WeightsMismatch(f"its {name}: {exc}") from None

    def load_state_dict(self, state: dict) -> None:
        self.policy.load_state_dict(state["policy"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.obs_normalizer.rms.load_state_dict(state["obs_normalizer"])
        self.privileged_normalizer.rms.load_state_dict(state["privileged_normalizer"])
        self.reward_scaler.rms.load_state_dict(state["reward_scaler"])
        self.generator.set_state(state["generator"])
        self.seed = state["seed"]  # env reset seeds derive from it
        self.global_step = state["global_step"]
        self.num_updates = state["num_updates"]
        self.progress = state["progress"]
        self._env_resets = state["env_resets"]
        # absent in checkpoints written before they existed
        self.critic_warmup_until = state.get("critic_warmup_until", 0)
        self.observation_stats_frozen = state.get("observation_stats_frozen", False)
        self.reset_envs()
