"""LunarLanderContinuous: taskforge PPO vs Stable-Baselines3 PPO (RL-Zoo hyperparameters), mean
held-out return vs env steps over several seeds, side by side.

    python benchmarks/lunar_lander.py [--seeds 0 1 2] [--steps 500000] [--resume]

Both learners use the RL-Zoo settings (agents/ppo_lunar_lander.yaml mirrors them) and are
evaluated the same way every 50k steps: 20 deterministic episodes on held-out reset seeds
1,000,000.. (never used in training). Goal: mean return >= 200 within 500k steps. Each run's
result is stored as it finishes, so `--resume` after an interruption redoes only what is
missing (taskforge runs also resume from their own checkpoints).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import RESULTS, print_table, versions, write_result  # noqa: E402
from taskforge.backends.gymnasium_env import TEST_SEED_OFFSET  # noqa: E402
from taskforge.run import RunDir  # noqa: E402
from taskforge.spec import load_agent_spec  # noqa: E402
from taskforge.training import train  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CURRICULUM = ROOT / "curricula/lunar_lander.yaml"
AGENT = ROOT / "agents/ppo_lunar_lander.yaml"
ENV_ID = "LunarLanderContinuous-v3"
EVAL_EVERY, EVAL_EPISODES = 50_000, 20
RUNS = ROOT / "benchmarks/runs/lunar_lander"


def run_taskforge(seed: int, steps: int) -> list[tuple[int, float]]:
    run_dir = RUNS / f"taskforge-seed{seed}"
    train(CURRICULUM, run_dir=run_dir, seed=seed, steps=steps, resume=True, progress=False)  # afresh when new
    return [(m["step"], m["eval_return_mean"]) for m in RunDir(run_dir).read_metrics() if "eval_return_mean" in m]


def run_sb3(seed: int, steps: int) -> list[tuple[int, float]]:
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env

    spec = load_agent_spec(AGENT)
    ppo = spec.ppo
    curve: list[tuple[int, float]] = []

    class HeldOutEval(BaseCallback):
        def __init__(self):
            super().__init__()
            self.next = EVAL_EVERY

        def _on_step(self) -> bool:
            if self.num_timesteps >= self.next:
                self.next += EVAL_EVERY
                env = gym.make(ENV_ID)
                returns = []
                for k in range(EVAL_EPISODES):
                    obs, _ = env.reset(seed=TEST_SEED_OFFSET + k)
                    done, total = False, 0.0
                    while not done:
                        action, _ = self.model.predict(obs, deterministic=True)
                        obs, r, te, tr, _ = env.step(action)
                        total += r
                        done = te or tr
                    returns.append(total)
                curve.append((self.num_timesteps, float(np.mean(returns))))
            return True

    venv = make_vec_env(ENV_ID, n_envs=ppo.num_envs, seed=seed)
    model = PPO(
        "MlpPolicy", venv, n_steps=ppo.rollout_steps, batch_size=ppo.num_envs * ppo.rollout_steps // ppo.num_minibatches,
        gae_lambda=ppo.gae_lambda, gamma=ppo.gamma, n_epochs=ppo.update_epochs, ent_coef=ppo.ent_coef,
        learning_rate=ppo.learning_rate, seed=seed, device="cpu",
    )
    model.learn(steps, callback=HeldOutEval())
    return curve


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=500_000)
    parser.add_argument("--resume", action="store_true", help="keep finished runs from a previous call")
    args = parser.parse_args()
    torch.set_num_threads(1)
    partial_file = RESULTS / "lunar_lander.partial.json"
    done: dict[str, dict] = json.loads(partial_file.read_text()) if args.resume and partial_file.exists() else {}
    for seed in args.seeds:
        for learner, fn in (("taskforge", run_taskforge), ("sb3", run_sb3)):
            key = f"{learner}-seed{seed}"
            if key in done and done[key]["steps"] >= args.steps:
                continue
            start = time.perf_counter()
            curve = fn(seed, args.steps)
            done[key] = {"learner": learner, "seed": seed, "steps": args.steps, "curve": curve,
                         "wall_s": time.perf_counter() - start}
            RESULTS.mkdir(parents=True, exist_ok=True)
            partial_file.write_text(json.dumps(done, indent=1))
            print(f"{key}: final held-out return {curve[-1][1]:.1f} ({done[key]['wall_s']:.0f} s)", flush=True)

    def bucket(step: int) -> int:
        """taskforge evaluates after the first update past each 50k mark (updates are 16,384
        steps), SB3 exactly at it: compare them per 50k bucket."""
        return step // EVAL_EVERY * EVAL_EVERY

    checkpoints = sorted({bucket(s) for run in done.values() for s, _ in run["curve"]})
    rows, summary = [], {}
    for learner in ("taskforge", "sb3"):
        runs = [r for r in done.values() if r["learner"] == learner]
        by_step = {s: [{bucket(k): v for k, v in r["curve"]}.get(s) for r in runs] for s in checkpoints}
        means = {s: float(np.mean([v for v in vals if v is not None])) for s, vals in by_step.items() if any(v is not None for v in vals)}
        summary[learner] = {"mean_return_by_step": means, "final_per_seed": [r["curve"][-1][1] for r in runs],
                            "wall_s_per_seed": [r["wall_s"] for r in runs]}
    for s in checkpoints:
        rows.append([f"{s:,}", *(f"{summary[k]['mean_return_by_step'].get(s, float('nan')):.1f}" for k in ("taskforge", "sb3"))])
    print_table(["env steps", "taskforge (mean of seeds)", "SB3 RL-Zoo (mean of seeds)"], rows)
    for k in ("taskforge", "sb3"):
        final = summary[k]["final_per_seed"]
        print(f"{k}: final held-out return per seed {', '.join(f'{x:.0f}' for x in final)}; "
              f"goal >= 200: {'met' if np.mean(final) >= 200 else 'NOT met'}")
    write_result("lunar_lander", {"seeds": args.seeds, "steps": args.steps, "eval": f"{EVAL_EPISODES} episodes every {EVAL_EVERY:,} steps on held-out seeds",
                                  "summary": summary, "runs": done, "versions": versions("torch", "stable-baselines3", "gymnasium", "box2d")})


if __name__ == "__main__":
    main()
