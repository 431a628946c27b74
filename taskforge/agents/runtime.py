"""Vector envs the agent can train on and torch's thread count, from `AgentSpec.runtime`; whether
a torch device an agent names is present."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator, Sequence

import gymnasium
import torch
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, SyncVectorEnv, VectorEnv

from taskforge.agents.ray_shards import RestartCallback, ray_vector_env
from taskforge.agents.sharded import ShardedVectorEnv
from taskforge.spec.agent import RuntimeSpec


def make_vector_env(env_fns: Sequence[Callable[[], gymnasium.Env]], runtime: RuntimeSpec,
                    on_restart: RestartCallback | None = None) -> VectorEnv:
    """A gymnasium vector env (core detail #1) with SAME_STEP autoreset, which `PPOAgent.collect`
    requires.

    SAME_STEP resets a finished env inside the step that ended it: the step returns the new
    episode's first observation and puts the last one in `infos["final_obs"]` (its info in
    `infos["final_info"]`), which is exactly what truncation bootstrapping needs. NEXT_STEP
    instead spends an extra step with a dummy action and reward 0 on the reset.

    `on_restart` hears of each Ray worker that died and was restarted (`vector: ray` only).
    """
    if runtime.vector == "sharded":
        return ShardedVectorEnv(env_fns, runtime.workers or os.cpu_count() or 1)
    if runtime.vector == "ray":
        return ray_vector_env(env_fns, runtime.workers, runtime.ray_address, runtime.ray_max_restarts, on_restart)
    vector_cls = AsyncVectorEnv if runtime.vector == "async" else SyncVectorEnv
    return vector_cls(env_fns, autoreset_mode=AutoresetMode.SAME_STEP)


def check_same_step_autoreset(envs: VectorEnv) -> None:
    """Raise unless `envs` resets finished episodes in the same step (see `make_vector_env`)."""
    mode = envs.metadata.get("autoreset_mode")
    if mode != AutoresetMode.SAME_STEP:
        raise ValueError(
            f"PPOAgent needs a vector env with autoreset_mode=AutoresetMode.SAME_STEP (got {mode!r}): "
            "it bootstraps truncated episodes from infos['final_obs']. "
            "Build it with taskforge.agents.make_vector_env."
        )


def set_torch_threads(runtime: RuntimeSpec) -> None:
    """`torch.set_num_threads(runtime.torch_threads)`: small networks run fastest on one or two
    threads, and envs in other processes need the remaining cores. Denormals are flushed first
    (`flush_denormals`), before the threads start."""
    flush_denormals()
    torch.set_num_threads(runtime.torch_threads)


def flush_denormals() -> None:
    """Flush denormal floats to zero (x86's FTZ/DAZ) in this thread and every thread torch starts
    after it; call it before an agent's first tensor op.

    Why: weight decay drives a network's unused weights toward zero through float32's denormal
    range (below 1.2e-38), where an Intel CPU takes a microcode assist on each multiply. Measured
    on a 2-core Intel Xeon: Meta-World push's MPC model after 28k steps (5% of one layer's
    weights denormal) planned a step for 4 envs in 1.2 s instead of 0.10 s, and the run slowed
    12x within 8k steps (an AMD EPYC, where earlier runs trained, barely slows). The flag belongs
    to each thread, and a thread takes its creator's when it starts, so it must be set before
    torch starts its worker threads: set later, it reached the main thread only and planning
    stayed at 1.2 s. What a model predicts does not move: zeroing that model's denormal weights
    changed none of its predictions by a single bit (the flag also zeroes denormal products, each
    below 1.2e-38). TensorFlow flushes in its own threads by default."""
    torch.set_flush_denormal(True)


def update_threads(runtime: RuntimeSpec) -> int:
    """Torch threads for the PPO update: by default every core, since the env workers wait for
    the new policy and their cores would otherwise idle."""
    return runtime.update_threads or os.cpu_count() or 1


@contextlib.contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run a block with `n` torch threads, then restore the previous count."""
    previous = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def device_available(name: str) -> bool:
    """Whether torch can use the device `name` (`cpu`, `cuda`, `cuda:N`) on this machine."""
    device = torch.device(name)
    if device.type == "cpu":
        return True
    return torch.cuda.is_available() and (device.index or 0) < torch.cuda.device_count()
