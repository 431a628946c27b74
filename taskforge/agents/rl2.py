"""RL² (Duan et al., 2016, "RL²: Fast Reinforcement Learning via Slow Reinforcement Learning"):
the learning algorithm is the recurrent policy's hidden state.

RL² is PPO with two changes, both here:

1. The env is seen in **trials**: `RL2Trial` plays K episodes of one task (one goal, one physics
   draw) back to back and reports them to the agent as a single episode. The agent's recurrent
   state is reset only where its env reports an episode start, so it persists across the K
   episodes and resets between trials, and GAE runs across the inner episode boundaries: RL²
   maximises the return of the whole trial, so exploring in episode 1 pays off in episode K.
2. The policy's input is `concat(obs, previous action, previous reward, episode-start flag)`, so
   the state can accumulate what the rewards said about the hidden goal.

Everything else (GRU core, sequence minibatches cut into BPTT chunks, the PPO loss) is the
recurrent PPO of `ppo.py` and `policies.py`; `algo: rl2` in an agent preset switches this on.

The wrapped env must accept `reset(options={"same_task": True})`, meaning "a new episode of the
task and goal you are on" (`TaskEnv` does), and may put `episode_success` in its step info.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium.spaces import Box

from taskforge.spec.agent import AgentSpec

SAME_TASK = {"same_task": True}


def trial_observation_space(obs_space: Box, action_space: Box) -> Box:
    """`concat(obs, previous action, previous reward, episode-start flag)`."""
    low = np.concatenate([obs_space.low, action_space.low, [-np.inf, 0.0]]).astype(np.float32)
    high = np.concatenate([obs_space.high, action_space.high, [np.inf, 1.0]]).astype(np.float32)
    return Box(low, high, dtype=np.float32)


class RL2Trial(gymnasium.Wrapper):
    """Plays `trial_episodes` episodes of one task as one episode.

    Inner episode ends are not reported: the wrapper resets the env with `same_task` inside the
    step and returns the new episode's first observation with the episode-start flag set. The
    trial ends (`terminated=True`: nothing follows it, so nothing is bootstrapped) with the K-th
    episode, and the last step's info then carries `trial_successes`, `trial_returns` and
    `trial_lengths` (one entry per episode of the trial: the adaptation curve).

    With `augment=True` (RL²) observations are `concat(obs, a_{t-1}, r_{t-1}, start_t)`, where
    `a_{t-1}` is the action the env received (clipped to the action box), `r_{t-1}` the reward
    of that step times `reward_scale` (`rl2.reward_input_scale`) and `start_t` is 1 on the first observation of every episode; on the trial's
    first observation the action and reward are zeros. With `augment=False` observations pass
    through unchanged: how a memoryless policy is evaluated over the same trials.
    """

    def __init__(self, env: gymnasium.Env, trial_episodes: int, augment: bool = True, reward_scale: float = 1.0) -> None:
        super().__init__(env)
        if trial_episodes < 1:
            raise ValueError(f"trial_episodes must be >= 1, got {trial_episodes}")
        self.trial_episodes = trial_episodes
        self.augment = augment
        self.reward_scale = reward_scale
        if augment:
            self.observation_space = trial_observation_space(env.observation_space, env.action_space)
        self._no_action = np.zeros(env.action_space.shape, dtype=np.float32)
        self._episode_return = 0.0
        self._episode_length = 0
        self._successes: list[bool] = []
        self._returns: list[float] = []
        self._lengths: list[int] = []

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start a trial: the env's own reset draws the task and goal (from `options`, or its
        defaults), which then hold for all K episodes."""
        obs, info = self.env.reset(seed=seed, options=options)
        self._successes, self._returns, self._lengths = [], [], []
        self._episode_return, self._episode_length = 0.0, 0
        return self._observe(obs, self._no_action, 0.0, start=True), info

    def step(self, action: np.ndarray):
        action = np.clip(np.asarray(action, dtype=np.float32), self.env.action_space.low, self.env.action_space.high)
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._episode_return += float(reward)
        self._episode_length += 1
        if not (terminated or truncated):
            return self._observe(obs, action, reward, start=False), reward, False, False, info

        self._successes.append(bool(info.get("episode_success", False)))
        self._returns.append(self._episode_return)
        self._lengths.append(self._episode_length)
        self._episode_return, self._episode_length = 0.0, 0
        if len(self._successes) == self.trial_episodes:
            trial = {
                "trial_successes": np.array(self._successes),
                "trial_returns": np.array(self._returns),
                "trial_lengths": np.array(self._lengths),
            }
            return self._observe(obs, action, reward, start=False), reward, True, False, {**info, **trial}
        # the trial goes on: a new episode of the same task, inside this step
        obs, info = self.env.reset(options=SAME_TASK)
        return self._observe(obs, action, reward, start=True), reward, False, False, info

    def _observe(self, obs: np.ndarray, action: np.ndarray, reward: float, start: bool) -> np.ndarray:
        if not self.augment:
            return obs
        return np.concatenate([obs, action, [reward * self.reward_scale, float(start)]]).astype(np.float32)


def agent_observation_space(spec: AgentSpec, obs_space: Box, action_space: Box) -> Box:
    """What the agent's policy reads from an env with these spaces."""
    return trial_observation_space(obs_space, action_space) if spec.algo == "rl2" else obs_space


def wrap_for_training(env: gymnasium.Env, spec: AgentSpec) -> gymnasium.Env:
    """The env as the agent trains on it: trials of augmented observations for RL², else as is."""
    return RL2Trial(env, spec.trial_episodes, reward_scale=spec.rl2.reward_input_scale) if spec.rl2 is not None else env
