"""`runtime.vector: ray` against `sharded` on this machine, in one run, and what a cluster would
change by arithmetic from the measured parts.

    python benchmarks/ray_overhead.py [--steps 4000] [--repeats 3] [--envs 8 16 32]

Rows (the same pre-drawn random actions, alternating row by row so machine noise hits both
alike; medians over `--repeats`):
- vector steps/s of taskforge's pick-place env (tasks/metaworld/pick_place.yaml, `place`, full
  randomisation) in `sharded` (one worker process + the learner's own slice) and `ray` (one Ray
  actor + the learner's own slice), each `--envs` count in 2 slices; goal (issue 22): ray >= 0.9 x;
- the parts the cluster arithmetic needs, at the first `--envs` count: one slice of half the envs
  stepped in-process (the per-worker rate), a Ray actor's round trip with nothing to do, and the
  policy's forward pass for the cluster's envs (the learner's share of a step).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, versions, write_result  # noqa: E402
from benchmarks.pick_place_envs import taskforge_env  # noqa: E402
from taskforge.agents import PPOAgent, make_vector_env  # noqa: E402
from taskforge.agents.ray_shards import connect  # noqa: E402
from taskforge.agents.sharded import _Shard  # noqa: E402
from taskforge.spec import AgentSpec, load_agent_spec  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def vector_rate(vector: str, envs: int, actions: np.ndarray) -> float:
    runtime = AgentSpec.model_validate({"name": "bench", "runtime": {"vector": vector, "workers": 2}}).runtime
    venv = make_vector_env([taskforge_env] * envs, runtime)
    venv.reset(seed=0)
    start = time.perf_counter()
    for batch in actions:
        venv.step(batch)
    rate = actions.shape[0] * envs / (time.perf_counter() - start)
    venv.close()
    return rate


def slice_rate(envs: int, actions: np.ndarray) -> float:
    """Env steps/s of one slice stepped in this process: what one worker (actor) delivers."""
    shard = _Shard([taskforge_env] * envs)
    shard.handle("reset", {"seeds": list(range(envs)), "options": None})
    start = time.perf_counter()
    for batch in actions:
        shard.step(batch[:envs])
    return actions.shape[0] * envs / (time.perf_counter() - start)


def ray_round_trip(calls: int) -> float:
    """Seconds per call to an actor that does nothing: Ray's fixed cost per vector step."""
    ray = connect(None)

    @ray.remote(num_cpus=1)
    class Idle:
        def ping(self, x: np.ndarray) -> np.ndarray:
            return x

    actor = Idle.remote()
    payload = np.zeros((4, 4), dtype=np.float32)
    ray.get(actor.ping.remote(payload))
    start = time.perf_counter()
    for _ in range(calls):
        ray.get(actor.ping.remote(payload))
    seconds = (time.perf_counter() - start) / calls
    ray.kill(actor)
    return seconds


def policy_seconds(envs: int, obs_size: int, action_size: int, calls: int) -> float:
    """The headline preset's forward pass for `envs` observations (one thread, as collecting)."""
    import gymnasium

    torch.set_num_threads(1)
    spec = load_agent_spec(ROOT / "agents/ppo.yaml")
    spec = spec.model_copy(update={"ppo": spec.ppo.model_copy(update={"num_envs": envs})})
    obs_space = gymnasium.spaces.Box(-np.inf, np.inf, (obs_size,), np.float32)
    act_space = gymnasium.spaces.Box(-1, 1, (action_size,), np.float32)
    agent = PPOAgent(spec, obs_space, act_space, seed=0)
    obs = np.zeros((envs, obs_size), dtype=np.float32)
    start = time.perf_counter()
    for _ in range(calls):
        agent.act(obs)
    return (time.perf_counter() - start) / calls


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000, help="vector steps x envs per measurement")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--envs", type=int, nargs="+", default=[8, 16, 32],
                        help="env counts to compare at (8: the headline preset's)")
    args = parser.parse_args()
    probe = taskforge_env()
    obs_size, action_size = probe.observation_space.shape[0], probe.action_space.shape[0]
    probe.close()
    rng = np.random.default_rng(0)

    rows, measured = [], {}
    for envs in args.envs:
        actions = rng.uniform(-1, 1, (args.steps // envs, envs, action_size)).astype(np.float32)
        rates: dict[str, list[float]] = {"sharded": [], "ray": []}
        for _ in range(args.repeats):
            for vector in rates:
                rates[vector].append(vector_rate(vector, envs, actions))
        median = {k: statistics.median(v) for k, v in rates.items()}
        measured[envs] = {"runs": rates, "median": median, "ray_over_sharded": median["ray"] / median["sharded"]}
        rows.append([envs, median["sharded"], median["ray"], f"{median['ray'] / median['sharded']:.2f}",
                     " / ".join(" ".join(f"{r:,.0f}" for r in rates[k]) for k in rates)])
    print_table(["envs", "sharded env steps/s", "ray env steps/s", "ray / sharded (goal >= 0.9)", "runs (sharded / ray)"], rows)
    envs = args.envs[0]
    actions = rng.uniform(-1, 1, (args.steps // envs, envs, action_size)).astype(np.float32)
    per_slice = statistics.median(slice_rate(envs // 2, actions) for _ in range(args.repeats))
    rtt = statistics.median(ray_round_trip(500) for _ in range(args.repeats))
    print(f"\none slice of {envs // 2} envs in-process: {per_slice:,.0f} env steps/s; Ray actor round trip {rtt * 1e3:.2f} ms")

    # A cluster of N such 2-core nodes, one slice per core (the learner's node steps one slice
    # itself), `per_core` envs per slice as here: a vector step takes the slowest slice's time
    # plus a round trip plus the learner's forward pass for all envs; more nodes add envs, not
    # env time per step
    # (measured for that batch). The PPO update is not in it: it costs the same per sample
    # wherever the samples came from.
    per_core = envs // 2
    slice_seconds = per_core / per_slice
    cluster = []
    for nodes in (1, 2, 4):
        envs = 2 * nodes * per_core
        step_seconds = slice_seconds + rtt + policy_seconds(envs, obs_size, action_size, 200)
        cluster.append({"nodes": nodes, "envs": envs, "predicted_env_steps_per_s": envs / step_seconds})
    print_table(["nodes (2 cores each)", "envs", "predicted env steps/s (collecting)"],
                [[c["nodes"], c["envs"], c["predicted_env_steps_per_s"]] for c in cluster])
    path = write_result("ray_overhead", {
        "envs": args.envs, "steps": args.steps, "repeats": args.repeats, "by_envs": measured,
        "slice_env_steps_per_s": per_slice, "slice_envs": per_core, "ray_round_trip_s": rtt,
        "cluster_prediction": cluster, "versions": versions("ray", "torch", "mujoco", "metaworld"),
    })
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
