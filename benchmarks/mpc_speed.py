"""What `algo: mpc` costs per env step on this machine's CPU and, where torch finds one, its GPU:
one planning call (it plans for every env at once) and one model fit, for the shipped presets and
for the search PETS itself ran, side by side in one process.

    python benchmarks/mpc_speed.py [--envs 4 32] [--calls 20] [--seconds 10] [--threads 2] [--buffer 50000]

Why random weights and random transitions: a planning call's cost is its arithmetic (candidates x
particles x horizon x iterations rows through the ensemble, one layer after another), whatever
the weights learnt, so no training is needed to time it; the sizes are Meta-World's (39-number
observations, 4-number actions). What it leaves out is the env's own step (~1 ms for Meta-World
here), which `benchmarks/model_based.py`'s runs include in their ms per env step.

Columns: ms per planning call for `--envs` envs (a warm-up call excluded; a call ends when its
actions are back in host memory, so a GPU's queue is drained), the same per env step, and ms per
model fit (`model_updates` Adam steps on a buffer of `--buffer` transitions, plus the terminal
value's as many steps where the preset has one). Per env step in training = planning per env step
+ fit / `steps_per_update` + the env's step. The CPU runs with `--threads` torch threads (the
presets' `runtime.torch_threads` is 2: the dev container's cores).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch
from gymnasium.spaces import Box

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import print_table, versions, write_result  # noqa: E402
from taskforge.agents import MPCAgent  # noqa: E402
from taskforge.agents.mpc import UNTAGGED  # noqa: E402
from taskforge.spec import AgentSpec, load_agent_spec  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OBS, ACTIONS = 39, 4  # Meta-World's observation and action sizes
# PETS's own search (Chua et al. 2018, their cartpole/half-cheetah settings): 4 x 200 units,
# 500 candidates, 50 elites, 5 CEM rounds, 30-step horizon, 20 particles
PETS = {"hidden_sizes": [200, 200, 200, 200], "population": 500, "elites": 50, "iterations": 5, "horizon": 30, "particles": 20}


def presets() -> dict[str, AgentSpec]:
    """The shipped MPC presets, and agents/mpc_large.yaml with PETS's search."""
    small, large = load_agent_spec(ROOT / "agents/mpc.yaml"), load_agent_spec(ROOT / "agents/mpc_large.yaml")
    return {"agents/mpc.yaml": small, "agents/mpc_large.yaml": large, "mpc_large + PETS's search": large.with_planning(**PETS)}


def time_planning(agent: MPCAgent, envs: int, calls: int, seconds: float, rng: np.random.Generator) -> tuple[float, int]:
    """Mean ms of one `act` for `envs` observations after a warm-up call, and how many calls were
    timed: `calls`, or fewer where they would take over `seconds`; none where the warm-up call
    alone took longer (PETS's search on a CPU: its time is then the warm-up's)."""
    obs = rng.uniform(-1, 1, (envs, OBS)).astype(np.float32)
    start = time.perf_counter()
    _, state = agent.act(obs, agent.initial_state(envs))
    if time.perf_counter() - start > seconds:
        return (time.perf_counter() - start) * 1000, 0
    start, timed = time.perf_counter(), 0
    while timed < calls and (timed == 0 or time.perf_counter() - start < seconds):
        _, state = agent.act(obs, state)  # returns numpy actions: the device is synchronised
        timed += 1
    return (time.perf_counter() - start) / timed * 1000, timed


def time_fit(agent: MPCAgent, transitions: int, rng: np.random.Generator) -> float:
    """ms of one `update` (the model's fit, and the value's) on `transitions` random transitions."""
    obs = rng.uniform(-1, 1, (transitions, OBS)).astype(np.float32)
    agent.buffer.add(obs, rng.uniform(-1, 1, (transitions, ACTIONS)), rng.normal(size=transitions), obs + 0.01 * rng.normal(size=obs.shape),
                     np.full(transitions, UNTAGGED))
    agent.update()  # warm-up (kernels, allocator)
    start = time.perf_counter()
    agent.update()  # ends in `.item()`s: synchronised
    return (time.perf_counter() - start) * 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, nargs="+", default=[4, 32], help="envs planned for in one call")
    parser.add_argument("--calls", type=int, default=20, help="timed planning calls per row (at most)")
    parser.add_argument("--seconds", type=float, default=10.0, help="stop timing a row's calls after this long (at least one)")
    parser.add_argument("--threads", type=int, default=2, help="torch threads on the CPU")
    parser.add_argument("--buffer", type=int, default=50_000, help="transitions in the buffer a fit reads")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    devices = (["cuda"] if torch.cuda.is_available() else []) + ["cpu"]  # the slow CPU rows last
    space, actions = Box(-np.inf, np.inf, (OBS,), np.float32), Box(-1.0, 1.0, (ACTIONS,), np.float32)
    gpu = torch.cuda.get_device_name() if torch.cuda.is_available() else None
    rows: list[list] = []
    records: list[dict] = []
    for name, spec in presets().items():
        mpc = spec.planning
        for device in devices:
            rng = np.random.default_rng(0)
            agent = MPCAgent(spec.with_planning(device=device), space, actions, seed=0)
            fit_ms = time_fit(agent, args.buffer, rng)
            too_slow = False  # a bigger batch only costs more: once a call outlasts --seconds, stop
            for envs in sorted(args.envs):
                if too_slow:
                    rows.append([name, device, envs, "skipped: a smaller batch took over --seconds a call", "", fit_ms, ""])
                    continue
                call_ms, timed = time_planning(agent, envs, args.calls, args.seconds, rng)
                too_slow = timed == 0
                per_step = call_ms / envs + fit_ms / mpc.steps_per_update
                records.append({"preset": name, "device": device, "envs": envs, "plan_ms_per_call": call_ms, "calls_timed": timed,
                                "plan_ms_per_env_step": call_ms / envs, "fit_ms": fit_ms, "steps_per_update": mpc.steps_per_update,
                                "ms_per_env_step_without_env": per_step, "hidden_sizes": mpc.hidden_sizes,
                                "search": {k: getattr(mpc, k) for k in ("population", "iterations", "horizon", "particles")}})
                rows.append([name, device, envs, call_ms, call_ms / envs, fit_ms, per_step])
                print(f"{name} on {device}, {envs} envs: {call_ms:,.1f} ms a planning call, {fit_ms:,.0f} ms a fit", flush=True)
                # written after every row: a run cut short keeps what it measured
                path = write_result("mpc_speed", {"gpu": gpu, "torch_threads": args.threads, "buffer": args.buffer,
                                                  "calls": args.calls, "versions": versions("torch"), "rows": records})
    print_table(["preset", "device", "envs", "plan ms/call", "plan ms/env step", "fit ms", "ms/env step (no env)"], rows)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
