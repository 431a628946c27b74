"""Training throughput on pick-place-v3: taskforge PPO vs Stable-Baselines3 PPO with the same
hyperparameters, and the envs alone, in one run.

    python benchmarks/ppo_throughput.py [--updates 4] [--agent agents/ppo.yaml]

Rows, each over every core:
- "taskforge env alone": taskforge's pick-place `place` env (full randomisation) in the sharded
  vector env, random actions: the ceiling for a learner on it;
- "Meta-World's own env alone": the bare Meta-World env, same vectorisation;
- taskforge PPO (sharded vector env: one worker process plus the main process on 2 cores);
- SB3 PPO on the same taskforge env (SubprocVecEnv, one process per env; VecNormalize): learner
  against learner;
- SB3 PPO on Meta-World's own env: what a user of SB3 and Meta-World runs.
All learners use the preset's rollout length, epochs, minibatch size and network (separate
256x256 tanh actor and critic), observation and reward normalisation, and one torch thread while
collecting. The first update of each is warm-up (process start, goal generation), not timed.
Goals (issue 19): taskforge PPO >= 2 x SB3 PPO; >= 0.75 x the taskforge env alone.
"""

from __future__ import annotations

import argparse
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, versions, write_result  # noqa: E402
from benchmarks.pick_place_envs import MetaWorldEnv, taskforge_env  # noqa: E402
from taskforge.agents import PPOAgent, make_vector_env  # noqa: E402
from taskforge.spec import load_agent_spec  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def time_taskforge(spec, updates: int) -> float:
    envs = make_vector_env([partial(taskforge_env, i) for i in range(spec.ppo.num_envs)], spec.runtime)
    agent = PPOAgent(spec, envs.single_observation_space, envs.single_action_space, seed=0)
    agent.collect(envs)
    agent.update()  # warm-up
    start, steps = time.perf_counter(), agent.global_step
    for _ in range(updates):
        agent.collect(envs)
        agent.update()
    sps = (agent.global_step - steps) / (time.perf_counter() - start)
    envs.close()
    return sps


def time_sb3(spec, updates: int, make_env) -> float:
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    ppo, policy = spec.ppo, spec.policy
    venv = make_vec_env(make_env, n_envs=ppo.num_envs, vec_env_cls=SubprocVecEnv)
    venv = VecNormalize(venv, norm_obs=ppo.norm_obs, norm_reward=ppo.norm_reward, gamma=ppo.gamma)
    batch = ppo.num_envs * ppo.rollout_steps
    model = PPO(
        "MlpPolicy", venv, learning_rate=ppo.learning_rate, n_steps=ppo.rollout_steps,
        batch_size=batch // ppo.num_minibatches, n_epochs=ppo.update_epochs, gamma=ppo.gamma,
        gae_lambda=ppo.gae_lambda, clip_range=ppo.clip_coef, clip_range_vf=ppo.clip_coef if ppo.clip_vloss else None,
        ent_coef=ppo.ent_coef, vf_coef=ppo.vf_coef, max_grad_norm=ppo.max_grad_norm, device="cpu", seed=0,
        policy_kwargs={"net_arch": {"pi": list(policy.hidden_sizes), "vf": list(policy.hidden_sizes)},
                       "activation_fn": torch.nn.Tanh, "log_std_init": policy.init_log_std},
    )
    model.learn(batch)  # warm-up
    start = time.perf_counter()
    model.learn(batch * updates, reset_num_timesteps=False)
    sps = batch * updates / (time.perf_counter() - start)
    venv.close()
    return sps


def time_env(spec, updates: int, make_env) -> float:
    """Random actions through the learner's vectorisation: the env alone."""
    n, steps = spec.ppo.num_envs, spec.ppo.rollout_steps * (updates + 1)
    envs = make_vector_env([make_env] * n, spec.runtime)
    envs.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, 4)).astype(np.float32)
    envs.step(actions[0])
    start = time.perf_counter()
    for a in actions[1:]:
        envs.step(a)
    sps = (steps - 1) * n / (time.perf_counter() - start)
    envs.close()
    return sps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=4, help="timed PPO updates per learner")
    parser.add_argument("--agent", default=str(ROOT / "agents/ppo.yaml"))
    args = parser.parse_args()
    spec = load_agent_spec(args.agent)
    torch.set_num_threads(spec.runtime.torch_threads)

    results = {
        "taskforge env alone": time_env(spec, args.updates, taskforge_env),
        "Meta-World's own env alone": time_env(spec, args.updates, MetaWorldEnv),
        "taskforge PPO": time_taskforge(spec, args.updates),
        "SB3 PPO on the taskforge env": time_sb3(spec, args.updates, taskforge_env),
        "SB3 PPO on Meta-World's own env": time_sb3(spec, args.updates, MetaWorldEnv),
    }
    env_alone, sb3 = results["taskforge env alone"], results["SB3 PPO on the taskforge env"]
    best = results["taskforge PPO"]
    print_table(["", "steps/s", "x taskforge env alone", "x SB3 (same env)"],
                [[name, sps, f"{sps / env_alone:.2f}", f"{sps / sb3:.2f}"] for name, sps in results.items()])
    over_sb3, over_env = best / sb3, best / env_alone
    over_sb3_mw = best / results["SB3 PPO on Meta-World's own env"]
    print(f"taskforge PPO / SB3 PPO, same env = {over_sb3:.2f} (goal >= 2); "
          f"/ SB3 PPO on Meta-World's own env = {over_sb3_mw:.2f}; / taskforge env alone = {over_env:.2f} (goal >= 0.75)")
    batch = spec.ppo.num_envs * spec.ppo.rollout_steps
    path = write_result("ppo_throughput", {
        "agent_preset": args.agent,
        "num_envs": spec.ppo.num_envs,
        "timed_steps_per_learner": batch * args.updates,
        "torch_threads": spec.runtime.torch_threads,
        "steps_per_s": results,
        "taskforge_over_sb3_same_env": over_sb3,
        "taskforge_over_sb3_metaworld_env": over_sb3_mw,
        "taskforge_over_env_alone": over_env,
        "goals": {"taskforge_over_sb3": ">= 2", "taskforge_over_env_alone": ">= 0.75"},
        "versions": versions("torch", "stable-baselines3", "metaworld", "mujoco", "gymnasium"),
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
