"""A vector env that runs several envs per worker process ("shards").

Why not gymnasium's AsyncVectorEnv: it spends one process per env, so on a 2-core machine eight
Meta-World workers mean eight pipe round trips and a dozen context switches per vector step, and
the main process (which runs the policy) is starved while it sends actions. Here `num_workers`
processes (default: one per core) each step their slice of envs in a loop, so a vector step costs
one round trip per core. Each worker also batches its own slice (observations stacked, infos
merged with gymnasium's own `_add_info`), in parallel, and the main process only concatenates one
batch per worker: per-env info merging in the main process was ~0.3 ms of every vector step, time
in which every worker waits (benchmarks/env_speed.py). Semantics match gymnasium's SAME_STEP
autoreset exactly (the same `final_obs` / `final_info` layout; tested against SyncVectorEnv).

`send_step(k, actions)` / `recv_step(k)` step one worker's slice (`shards[k]`) without waiting for
the others: PPO's overlapped collection (`runtime.overlap`) chooses one slice's next actions
while the other slices step. `set_attr` expects no reply, so it may be sent while a slice is
stepping: each worker applies it after the step it is running (its pipe is first in, first out).

Workers ignore SIGINT: on Ctrl-C the main process saves its checkpoint and closes them.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
import traceback
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

EnvFn = Callable[[], gymnasium.Env]


class _Batcher:
    """gymnasium's `VectorEnv._add_info` for a batch of `num_envs` infos, usable in a worker."""

    _add_info = VectorEnv._add_info

    def __init__(self, num_envs: int):
        self.num_envs = num_envs


def _step_shard(envs: list[gymnasium.Env], actions: np.ndarray, batcher: _Batcher):
    """Step a worker's envs, SAME_STEP autoreset, and batch the results as a vector env would."""
    obs, rewards, terminated, truncated, infos = [], np.zeros(len(envs)), np.zeros(len(envs), bool), np.zeros(len(envs), bool), {}
    for i, (env, action) in enumerate(zip(envs, actions)):
        o, rewards[i], terminated[i], truncated[i], info = env.step(action)
        if terminated[i] or truncated[i]:  # SAME_STEP autoreset
            infos = batcher._add_info(infos, {"final_obs": o, "final_info": info}, i)
            o, info = env.reset()
        infos = batcher._add_info(infos, info, i)
        obs.append(o)
    return np.stack(obs), rewards, terminated, truncated, infos


def _worker(pipe, env_fns: list[EnvFn]) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    envs = [fn() for fn in env_fns]
    batcher = _Batcher(len(envs))
    while True:
        command, payload = pipe.recv()
        try:
            if command == "step":
                pipe.send(("ok", _step_shard(envs, payload, batcher)))
            elif command == "reset":
                infos: dict[str, Any] = {}
                obs = []
                for i, (env, seed) in enumerate(zip(envs, payload["seeds"])):
                    o, info = env.reset(seed=seed, options=payload["options"])
                    infos = batcher._add_info(infos, info, i)
                    obs.append(o)
                pipe.send(("ok", (np.stack(obs), infos)))
            elif command == "set_attr":  # no reply (see module doc); a failure is the next reply
                name, values = payload
                for env, value in zip(envs, values):
                    setattr(env.unwrapped, name, value)
            elif command == "get_attr":
                pipe.send(("ok", [getattr(env.unwrapped, payload) for env in envs]))
            elif command == "close":
                for env in envs:
                    env.close()
                pipe.send(("ok", None))
                return
            else:
                raise ValueError(f"unknown command {command!r}")
        except Exception:  # report to the main process, which raises it there
            pipe.send(("error", traceback.format_exc()))


def _merge_infos(shards: list[dict[str, Any]], sizes: list[int]) -> dict[str, Any]:
    merged: dict[str, Any] = {}
    for key in dict.fromkeys(k for shard in shards for k in shard):  # keys in first-seen order
        parts = [shard.get(key) for shard in shards]
        sample = next(p for p in parts if p is not None)
        if isinstance(sample, dict):
            merged[key] = _merge_infos([p if p is not None else {} for p in parts], sizes)
        else:
            merged[key] = np.concatenate([p if p is not None else _blank(sample, n) for p, n in zip(parts, sizes)])
    return merged


def _blank(like: np.ndarray, n: int) -> np.ndarray:
    """`n` rows of what `_add_info` leaves where an env had no value: None for objects, else 0."""
    if like.dtype == object:
        return np.full(n, None, dtype=object)
    return np.zeros((n, *like.shape[1:]), dtype=like.dtype)


class ShardedVectorEnv(VectorEnv):
    """`len(env_fns)` envs spread over `num_workers` processes, SAME_STEP autoreset."""

    def __init__(self, env_fns: Sequence[EnvFn], num_workers: int):
        self.num_envs = len(env_fns)
        num_workers = max(1, min(num_workers, self.num_envs))
        probe = env_fns[0]()
        self.single_observation_space = probe.observation_space
        self.single_action_space = probe.action_space
        self.metadata = {**probe.metadata, "autoreset_mode": AutoresetMode.SAME_STEP}
        probe.close()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        bounds = np.linspace(0, self.num_envs, num_workers + 1).astype(int)
        self.shards = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
        """The envs of each worker, in order."""
        self._in_flight: set[int] = set()
        ctx = mp.get_context()
        self._pipes, self._procs = [], []
        for sl in self.shards:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, list(env_fns[sl])), daemon=True)
            proc.start()
            child.close()
            self._pipes.append(parent)
            self._procs.append(proc)
        self.closed = False

    def _all(self, messages: Sequence[tuple[str, Any]]) -> list[Any]:
        if self._in_flight:
            raise RuntimeError(f"workers {sorted(self._in_flight)} are still stepping: recv_step them first")
        for pipe, message in zip(self._pipes, messages):
            pipe.send(message)
        return [self._reply(k) for k in range(len(self._pipes))]

    def _reply(self, k: int) -> Any:
        status, value = self._pipes[k].recv()
        if status == "error":
            raise RuntimeError(f"a vector-env worker failed:\n{value}")
        return value

    def send_step(self, k: int, actions: np.ndarray) -> None:
        """Start stepping worker k's envs (`shards[k]`) with `actions` (one row per env)."""
        if k in self._in_flight:
            raise RuntimeError(f"worker {k} is still stepping: recv_step({k}) first")
        self._pipes[k].send(("step", actions))
        self._in_flight.add(k)

    def recv_step(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Worker k's step results, as a vector env of its envs alone would return them."""
        if k not in self._in_flight:
            raise RuntimeError(f"worker {k} is not stepping: send_step({k}, ...) first")
        self._in_flight.discard(k)
        return self._reply(k)

    def merge_infos(self, shards: Sequence[dict[str, Any]]) -> dict[str, Any]:
        """The workers' batched infos (one per worker, in order) as one vector env's: each array
        the concatenation of the workers' rows, a worker without a key contributing blank rows
        (mask false), as gymnasium's `_add_info` would have left them."""
        return _merge_infos(list(shards), [sl.stop - sl.start for sl in self.shards])

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        replies = self._all([("reset", {"seeds": seeds[sl], "options": options}) for sl in self.shards])
        return np.concatenate([obs for obs, _ in replies]), self.merge_infos([infos for _, infos in replies])

    def step(self, actions: np.ndarray):
        for k, sl in enumerate(self.shards):
            self.send_step(k, actions[sl])
        obs, rewards, terminated, truncated, infos = zip(*(self.recv_step(k) for k in range(len(self.shards))))
        return np.concatenate(obs), np.concatenate(rewards), np.concatenate(terminated), np.concatenate(truncated), self.merge_infos(infos)

    def set_attr(self, name: str, values: Any) -> None:
        """Sent without waiting for a reply: allowed while workers step (module doc)."""
        if not isinstance(values, (list, tuple)):
            values = [values] * self.num_envs
        for pipe, sl in zip(self._pipes, self.shards):
            pipe.send(("set_attr", (name, list(values[sl]))))

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return tuple(v for shard in self._all([("get_attr", name)] * len(self._pipes)) for v in shard)

    def close_extras(self, **kwargs: Any) -> None:
        if self.closed:
            return
        try:
            for k in sorted(self._in_flight):  # a collection interrupted mid-step: take its results
                self.recv_step(k)
            self._all([("close", None)] * len(self._pipes))
        except (BrokenPipeError, EOFError, RuntimeError):
            pass
        for proc in self._procs:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.terminate()
