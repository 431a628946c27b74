"""A vector env that splits its envs into slices ("shards"), one per core: the last stepped by
the main process itself, each other one by a worker process.

Why not gymnasium's AsyncVectorEnv: it spends one process per env, so on a 2-core machine eight
Meta-World workers mean eight pipe round trips and a dozen context switches per vector step, and
the main process (which runs the policy) is starved while it sends actions. Here `num_shards`
slices (default: one per core) each step their envs in a loop, so a vector step costs one round
trip per worker process, and none for the main process's own slice (`_InProcess`: on this VM a
process wake-up and round trip cost more than the 4 envs a worker steps; 8 taskforge envs ran at
~3,100 steps/s over 2 worker processes, ~4,700 over 1 worker + the main process). Each worker
also batches its own slice (observations stacked, infos merged with gymnasium's own `_add_info`),
in parallel, and the main process only concatenates one batch per slice (benchmarks/env_speed.py).
Semantics match gymnasium's SAME_STEP autoreset exactly (the same `final_obs` / `final_info`
layout; tested against SyncVectorEnv).

A double-buffered collector (PPO sampling one slice's next actions while the other slices step)
was built and measured here, and removed: with the main process stepping a slice itself it
collected ~15 % slower than lockstep (ARCHITECTURE.md, "Vector env").

Workers ignore SIGINT: on Ctrl-C the main process (interrupted in its own slice's step or while
waiting) saves its last complete checkpoint and closes them.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any, Protocol

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


class _Shard:
    """A slice of envs and the commands the vector env sends it; runs in a worker process or,
    for the last slice, in the main process itself (`_InProcess`)."""

    def __init__(self, env_fns: Sequence[EnvFn]):
        self.envs = [fn() for fn in env_fns]
        self.batcher = _Batcher(len(self.envs))

    def step(self, actions: np.ndarray):
        """Step the envs, SAME_STEP autoreset, and batch the results as a vector env would."""
        n = len(self.envs)
        obs, rewards, terminated, truncated, infos = [], np.zeros(n), np.zeros(n, bool), np.zeros(n, bool), {}
        for i, (env, action) in enumerate(zip(self.envs, actions)):
            o, rewards[i], terminated[i], truncated[i], info = env.step(action)
            if terminated[i] or truncated[i]:  # SAME_STEP autoreset
                infos = self.batcher._add_info(infos, {"final_obs": o, "final_info": info}, i)
                o, info = env.reset()
            infos = self.batcher._add_info(infos, info, i)
            obs.append(o)
        return np.stack(obs), rewards, terminated, truncated, infos

    def handle(self, command: str, payload: Any) -> tuple[str, Any]:
        """The reply to one command."""
        envs = self.envs
        if command == "step":
            return "ok", self.step(payload)
        if command == "reset":
            infos: dict[str, Any] = {}
            obs = []
            for i, (env, seed) in enumerate(zip(envs, payload["seeds"])):
                o, info = env.reset(seed=seed, options=payload["options"])
                infos = self.batcher._add_info(infos, info, i)
                obs.append(o)
            return "ok", (np.stack(obs), infos)
        if command == "set_attr":
            name, values = payload
            for env, value in zip(envs, values):
                setattr(env.unwrapped, name, value)
            return "ok", None
        if command == "get_attr":
            return "ok", [getattr(env.unwrapped, payload) for env in envs]
        if command == "close":
            for env in envs:
                env.close()
            return "ok", None
        raise ValueError(f"unknown command {command!r}")

    def run(self, command: str, payload: Any) -> tuple[str, Any]:
        """`handle`, with a failure turned into an error reply (raised in the main process)."""
        try:
            return self.handle(command, payload)
        except Exception:
            return "error", traceback.format_exc()


def _worker(pipe, env_fns: list[EnvFn]) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    shard = _Shard(env_fns)
    while True:
        command, payload = pipe.recv()
        pipe.send(shard.run(command, payload))
        if command == "close":
            return


class _InProcess:
    """The last slice of envs, stepped by the main process itself, behind the same send/recv
    interface as a worker's pipe. The main process only waits while the workers step; giving it
    a slice of its own replaces one worker's process wake-ups and pipe round trip per step, which
    on this 2-core VM cost more than the stepping (benchmarks/env_speed.py: 2 worker processes
    ran 8 envs *slower* than one process alone). Commands run when sent, so the vector env sends
    to the workers first."""

    def __init__(self, env_fns: Sequence[EnvFn]):
        self.shard = _Shard(env_fns)
        self.replies: deque[tuple[str, Any]] = deque()

    def send(self, message: tuple[str, Any]) -> None:
        self.replies.append(self.shard.run(*message))

    def recv(self) -> tuple[str, Any]:
        return self.replies.popleft()


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


class Channel(Protocol):
    """How the vector env talks to one slice: send a command, later receive its reply
    (`("ok", value)` or `("error", traceback)`), in order. A worker process's pipe, the main
    process's own slice (`_InProcess`) and a Ray actor (`taskforge.agents.ray_shards`) are
    channels."""

    def send(self, message: tuple[str, Any]) -> None: ...

    def recv(self) -> tuple[str, Any]: ...


class _WorkerProcess:
    """A slice in a worker process of this machine, behind its pipe."""

    def __init__(self, env_fns: Sequence[EnvFn]):
        ctx = mp.get_context()
        self.pipe, child = ctx.Pipe()
        self.process = ctx.Process(target=_worker, args=(child, list(env_fns)), daemon=True)
        self.process.start()
        child.close()

    def send(self, message: tuple[str, Any]) -> None:
        self.pipe.send(message)

    def recv(self) -> tuple[str, Any]:
        return self.pipe.recv()

    def close(self) -> None:
        self.process.join(timeout=5)
        if self.process.is_alive():
            self.process.terminate()


RemoteFactory = Callable[[Sequence[EnvFn], int], Channel]
"""Builds the channel of a slice stepped outside the main process, from its env constructors
and the index of its first env."""


class ShardedVectorEnv(VectorEnv):
    """`len(env_fns)` envs in `num_shards` slices (the last in this process, the others each
    behind a channel from `remote`: by default one worker process each), SAME_STEP autoreset."""

    def __init__(self, env_fns: Sequence[EnvFn], num_shards: int, remote: RemoteFactory | None = None):
        self.num_envs = len(env_fns)
        num_shards = max(1, min(num_shards, self.num_envs))
        probe = env_fns[0]()
        self.single_observation_space = probe.observation_space
        self.single_action_space = probe.action_space
        self.metadata = {**probe.metadata, "autoreset_mode": AutoresetMode.SAME_STEP}
        probe.close()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        bounds = np.linspace(0, self.num_envs, num_shards + 1).astype(int)
        self.shards = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
        """The envs of each slice, in order; the last one is stepped in this process."""
        remote = remote or (lambda fns, first: _WorkerProcess(fns))
        # the remote slices first: worker processes fork before this process builds envs
        self._pipes: list[Channel] = [remote(env_fns[sl], sl.start) for sl in self.shards[:-1]]
        self._pipes.append(_InProcess(env_fns[self.shards[-1]]))
        self.closed = False

    def _all(self, messages: Sequence[tuple[str, Any]]) -> list[Any]:
        """Send each slice its message (the workers first: the main process's own slice runs
        when sent), then collect the replies in order."""
        for pipe, message in zip(self._pipes, messages):
            pipe.send(message)
        replies = []
        for pipe in self._pipes:
            status, value = pipe.recv()
            if status == "error":
                raise RuntimeError(f"a vector-env worker failed:\n{value}")
            replies.append(value)
        return replies

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        replies = self._all([("reset", {"seeds": seeds[sl], "options": options}) for sl in self.shards])
        return np.concatenate([obs for obs, _ in replies]), self._merge([infos for _, infos in replies])

    def step(self, actions: np.ndarray):
        replies = self._all([("step", actions[sl]) for sl in self.shards])
        obs, rewards, terminated, truncated, infos = zip(*replies)
        return np.concatenate(obs), np.concatenate(rewards), np.concatenate(terminated), np.concatenate(truncated), self._merge(infos)

    def _merge(self, shards: Sequence[dict[str, Any]]) -> dict[str, Any]:
        """The slices' batched infos as one vector env's: each array the concatenation of the
        slices' rows, a slice without a key contributing blank rows (mask false), as gymnasium's
        `_add_info` would have left them."""
        return _merge_infos(list(shards), [sl.stop - sl.start for sl in self.shards])

    def set_attr(self, name: str, values: Any) -> None:
        if not isinstance(values, (list, tuple)):
            values = [values] * self.num_envs
        self._all([("set_attr", (name, list(values[sl]))) for sl in self.shards])

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return tuple(v for shard in self._all([("get_attr", name)] * len(self._pipes)) for v in shard)

    def close_extras(self, **kwargs: Any) -> None:
        if self.closed:
            return
        try:
            self._all([("close", None)] * len(self._pipes))
        except (BrokenPipeError, EOFError, RuntimeError):
            pass
        for pipe in self._pipes:
            close = getattr(pipe, "close", None)
            if close is not None:
                close()
