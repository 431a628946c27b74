"""Schema of an agent preset (`agents/*.yaml`): the policy network and PPO's hyperparameters.

Defaults follow CleanRL's `ppo_continuous_action.py`, which in turn follows the 37
implementation details of PPO (Huang et al., 2022).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from taskforge.spec.common import StrictModel


class PolicySpec(StrictModel):
    type: Literal["mlp", "lstm"] = "mlp"
    hidden_sizes: list[int] = Field(default_factory=lambda: [256, 256], min_length=1)
    activation: Literal["tanh", "relu", "elu"] = "tanh"
    lstm_hidden_size: int = Field(default=128, ge=1)
    """Width of the LSTM core (only for `type: lstm`)."""
    action_bounds: Literal["clip", "squash"] = "clip"
    """How Gaussian samples meet the action box: `clip` at the env boundary (CleanRL) or `squash`
    with tanh (log-prob corrected)."""
    init_log_std: float = Field(default=0.0, ge=-5.0, le=2.0)

    @model_validator(mode="after")
    def _positive_sizes(self) -> "PolicySpec":
        if any(h < 1 for h in self.hidden_sizes):
            raise ValueError(f"'hidden_sizes' must all be >= 1 (got {self.hidden_sizes})")
        return self


class PPOSpec(StrictModel):
    num_envs: int = Field(default=8, ge=1, le=1024)
    rollout_steps: int = Field(default=256, ge=1)
    """Steps per environment per update; batch size = num_envs * rollout_steps."""
    learning_rate: float = Field(default=3e-4, gt=0.0, le=1.0)
    anneal_lr: bool = True
    gamma: float = Field(default=0.99, ge=0.0, le=1.0)
    gae_lambda: float = Field(default=0.95, ge=0.0, le=1.0)
    update_epochs: int = Field(default=10, ge=1)
    num_minibatches: int = Field(default=32, ge=1)
    clip_coef: float = Field(default=0.2, gt=0.0)
    clip_vloss: bool = True
    ent_coef: float = Field(default=0.0, ge=0.0)
    vf_coef: float = Field(default=0.5, ge=0.0)
    max_grad_norm: float = Field(default=0.5, gt=0.0)
    target_kl: float | None = Field(default=None, gt=0.0)
    norm_adv: bool = True
    norm_obs: bool = True
    norm_reward: bool = True

    @model_validator(mode="after")
    def _minibatches_fit(self) -> "PPOSpec":
        batch = self.num_envs * self.rollout_steps
        if self.num_minibatches > batch:
            raise ValueError(
                f"'num_minibatches' ({self.num_minibatches}) exceeds the batch "
                f"num_envs*rollout_steps = {batch}"
            )
        return self


class RuntimeSpec(StrictModel):
    vector: Literal["sharded", "async", "sync"] = "sharded"
    """`sharded`: `workers` processes each stepping a slice of the envs (one round trip per core
    per step); `async`: one process per env (gymnasium AsyncVectorEnv); `sync`: all in-process."""
    workers: int | None = Field(default=None, ge=1, le=1024)
    """Worker processes for `sharded`; default one per CPU core."""
    torch_threads: int = Field(default=1, ge=1, le=256)
    """Torch threads while collecting: one, so the env workers keep the other cores."""
    update_threads: int | None = Field(default=None, ge=1, le=256)
    """Torch threads during the PPO update; default every core (the workers wait meanwhile)."""


class AgentSpec(StrictModel):
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_\-.]+$")
    algo: Literal["ppo"] = "ppo"
    policy: PolicySpec = PolicySpec()
    asymmetric_critic: bool = False
    """The critic also sees privileged features (object velocity, goal, drawn physics)."""
    ppo: PPOSpec = PPOSpec()
    runtime: RuntimeSpec = RuntimeSpec()

    @model_validator(mode="after")
    def _recurrent_minibatches(self) -> "AgentSpec":
        if self.policy.type == "lstm" and self.ppo.num_minibatches > self.ppo.num_envs:
            raise ValueError(
                f"an LSTM policy trains on whole env sequences, so ppo.num_minibatches "
                f"({self.ppo.num_minibatches}) must be <= ppo.num_envs ({self.ppo.num_envs})"
            )
        return self
