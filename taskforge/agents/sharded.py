"""A vector env that runs several envs per worker process ("shards").

Why not gymnasium's AsyncVectorEnv: it spends one process per env, so on a 2-core machine eight
Meta-World workers mean eight pipe round trips and a dozen context switches per vector step, and
the main process (which runs the policy) is starved while it sends actions. Here `num_workers`
processes (default: one per core) each step their slice of envs in a loop, so a vector step costs
one round trip per core. Semantics match gymnasium's SAME_STEP autoreset exactly (the same
`final_obs` / `final_info` layout, built with gymnasium's own `_add_info`).

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


def _worker(pipe, env_fns: list[EnvFn]) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    envs = [fn() for fn in env_fns]
    while True:
        command, payload = pipe.recv()
        try:
            if command == "step":
                results = []
                for env, action in zip(envs, payload):
                    obs, reward, terminated, truncated, info = env.step(action)
                    final = None
                    if terminated or truncated:  # SAME_STEP autoreset
                        final = {"final_obs": obs, "final_info": info}
                        obs, info = env.reset()
                    results.append((obs, reward, terminated, truncated, info, final))
                pipe.send(("ok", results))
            elif command == "reset":
                pipe.send(("ok", [env.reset(seed=s, options=payload["options"]) for env, s in zip(envs, payload["seeds"])]))
            elif command == "set_attr":
                name, values = payload
                for env, value in zip(envs, values):
                    setattr(env.unwrapped, name, value)
                pipe.send(("ok", None))
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
        self._slices = [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]
        ctx = mp.get_context()
        self._pipes, self._procs = [], []
        for sl in self._slices:
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, list(env_fns[sl])), daemon=True)
            proc.start()
            child.close()
            self._pipes.append(parent)
            self._procs.append(proc)
        self.closed = False

    def _all(self, messages: Sequence[tuple[str, Any]]) -> list[Any]:
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
        replies = self._all([("reset", {"seeds": seeds[sl], "options": options}) for sl in self._slices])
        obs, infos = [], {}
        for i, (o, info) in enumerate(r for shard in replies for r in shard):
            obs.append(o)
            infos = self._add_info(infos, info, i)
        return np.stack(obs), infos

    def step(self, actions: np.ndarray):
        replies = self._all([("step", actions[sl]) for sl in self._slices])
        obs, rewards, terminated, truncated, infos = [], [], [], [], {}
        for i, (o, r, te, tr, info, final) in enumerate(r for shard in replies for r in shard):
            obs.append(o)
            rewards.append(r)
            terminated.append(te)
            truncated.append(tr)
            if final is not None:
                infos = self._add_info(infos, final, i)
            infos = self._add_info(infos, info, i)
        return (np.stack(obs), np.array(rewards, dtype=np.float64), np.array(terminated, dtype=bool),
                np.array(truncated, dtype=bool), infos)

    def set_attr(self, name: str, values: Any) -> None:
        if not isinstance(values, (list, tuple)):
            values = [values] * self.num_envs
        self._all([("set_attr", (name, list(values[sl]))) for sl in self._slices])

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return tuple(v for shard in self._all([("get_attr", name)] * len(self._pipes)) for v in shard)

    def close_extras(self, **kwargs: Any) -> None:
        if self.closed:
            return
        try:
            self._all([("close", None)] * len(self._pipes))
        except (BrokenPipeError, EOFError, RuntimeError):
            pass
        for proc in self._procs:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.terminate()
