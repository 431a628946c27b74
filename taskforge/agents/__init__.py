"""taskforge's own PPO (torch), with CleanRL's fidelity and no knowledge of the simulator.

It imports only torch, numpy, gymnasium and `taskforge.spec`. A trainer builds the vector env
with `make_vector_env` (SAME_STEP autoreset, needed for time-limit bootstrapping) and drives a
`PPOAgent`:

    set_torch_threads(spec.runtime)
    envs = make_vector_env(env_fns, spec.runtime)
    agent = PPOAgent(spec, envs.single_observation_space, envs.single_action_space, seed=0)
    while agent.global_step < budget:
        agent.set_progress(agent.global_step / budget)
        agent.collect(envs, on_step=log_episodes)
        metrics = agent.update()

Modules, in reading order: `gae` (advantages), `normalization` (observation and reward
statistics), `actions` (clip vs squash), `policies` (MLP / LSTM / GRU actor-critic), `storage`
(rollout buffer and minibatches), `ppo` (the agent and the loss), `rl2` (RL²: trials and the
augmented observation), `runtime` (vector env, threads), `bc` (warm start: behaviour cloning and
value regression on demonstrations); model-based: `dynamics` (PETS's ensemble), `planners`
(random shooting, CEM, MPPI), `mpc` (the agent, with PPO's interface).
"""

from gymnasium.spaces import Box

from taskforge.agents.actions import ClipGaussian, SquashGaussian
from taskforge.agents.gae import compute_gae
from taskforge.agents.mpc import MPCAgent
from taskforge.agents.normalization import ObservationNormalizer, RewardScaler, RunningMeanStd
from taskforge.agents.policies import ActorCritic, RecurrentState
from taskforge.agents.ppo import PPOAgent, PPOLoss, explained_variance, ppo_loss
from taskforge.agents.rl2 import RL2Trial, agent_observation_space, trial_observation_space, wrap_for_training
from taskforge.agents.runtime import check_same_step_autoreset, make_vector_env, set_torch_threads
from taskforge.agents.storage import Minibatch, RolloutBuffer
from taskforge.agents.weights import WeightsMismatch
from taskforge.spec.agent import AgentSpec

Agent = PPOAgent | MPCAgent
"""What a trainer drives and `evaluate` plays: `collect`, `update`, `act`, `state_dict`."""


def make_agent(spec: AgentSpec, observation_space: Box, action_space: Box, privileged_dim: int = 0, seed: int = 0) -> Agent:
    """The agent `spec.algo` names: PPO (also RL², which is PPO over trials) or model-based MPC."""
    cls = MPCAgent if spec.algo == "mpc" else PPOAgent
    return cls(spec, observation_space, action_space, privileged_dim, seed)

__all__ = [
    "ActorCritic",
    "Agent",
    "MPCAgent",
    "ClipGaussian",
    "Minibatch",
    "ObservationNormalizer",
    "PPOAgent",
    "PPOLoss",
    "RL2Trial",
    "RecurrentState",
    "RewardScaler",
    "RolloutBuffer",
    "RunningMeanStd",
    "SquashGaussian",
    "WeightsMismatch",
    "agent_observation_space",
    "check_same_step_autoreset",
    "compute_gae",
    "explained_variance",
    "make_agent",
    "make_vector_env",
    "ppo_loss",
    "set_torch_threads",
    "trial_observation_space",
    "wrap_for_training",
]
