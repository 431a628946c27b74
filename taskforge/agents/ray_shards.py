"""`runtime.vector: ray`: the sharded vector env with its remote slices in Ray actors, placed
across a Ray cluster (`ray.init(address=...)`) or a local Ray instance.

Why Ray: it already does what a home-made multi-machine runner would have to: start workers on
other machines, ship them the env constructors (cloudpickle), move arrays, and restart a worker
whose process or node died. The learner stays in the process that runs `taskforge train`; it
steps the last slice itself, exactly as `sharded` does (`ShardedVectorEnv`), so the same seeds
give the same trajectories under both (tested).

A lost worker. Each actor is created with `max_restarts`: when its process or node dies, Ray
re-runs its constructor (fresh envs) elsewhere. The command in flight fails with
`RayActorError`; `_RayShard` then replays the attributes the trainer had set on those envs (the
curriculum's `next_episode`), resets them with new seeds, and answers the failed command:
a step is answered as if every env of the slice had been truncated there (the episode's last
observation and info are the ones before the failed step, its last reward 0), so PPO bootstraps
the lost episodes and the curriculum counts them like any other. The trainer hears of it
through `on_restart` and logs an event. Restarts beyond `max_restarts` raise.
"""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from taskforge.agents.sharded import EnvFn, ShardedVectorEnv, _Shard

_FINAL_KEYS = ("final_obs", "_final_obs", "final_info", "_final_info")
RESTART_SEED_STRIDE = 1_000_003
"""The n-th restart of a slice resets its envs with their first seeds + n * this (a prime, so
restarted envs do not replay seeds other envs use)."""

RESTART_WAIT_S = 300.0
"""How long a restarted actor may take to come back (a new node may have to start)."""

RestartCallback = Callable[[dict[str, Any]], None]


def import_ray() -> Any:
    """`ray`, or an error that says how to install it (it is an optional extra)."""
    try:
        import ray
    except ImportError as error:
        raise ImportError("runtime.vector 'ray' needs Ray: pip install 'taskforge[ray]'") from error
    return ray


def connect(address: str | None, log_to_driver: bool = False) -> Any:
    """Join the Ray cluster at `address` (or `RAY_ADDRESS`), or start a local instance on this
    machine's cores; a process already connected stays connected. `log_to_driver`: print what
    the workers print (a sweep's trials report their progress so); env workers stay quiet."""
    ray = import_ray()
    if not ray.is_initialized():
        ray.init(address=address, include_dashboard=False, log_to_driver=log_to_driver, configure_logging=False)
    return ray


class _ShardActor(_Shard):
    """A slice as a Ray actor. Each incarnation (the first, and each restart) has its own token,
    sent with every reply: a call Ray delivered to a restarted actor (whose envs were never
    reset) is told apart from one its predecessor answered."""

    def __init__(self, env_fns: Sequence[EnvFn]):
        super().__init__(env_fns)
        self.incarnation = uuid.uuid4().hex

    def run_here(self, command: str, payload: Any) -> tuple[str, tuple[str, Any]]:
        return self.incarnation, self.run(command, payload)


class _RayShard:
    """One slice in a Ray actor, behind `ShardedVectorEnv`'s channel interface (send, then recv
    in order). It remembers what a restarted actor needs: the attributes set on its envs, the
    seeds of their first reset, and the last observations and infos it returned."""

    def __init__(self, ray: Any, env_fns: Sequence[EnvFn], first: int, max_restarts: int,
                 on_restart: RestartCallback | None):
        self.ray, self.first, self.size = ray, first, len(env_fns)
        self.max_restarts, self.on_restart = max_restarts, on_restart
        actor_cls = ray.remote(num_cpus=1, max_restarts=max_restarts, max_task_retries=0)(_ShardActor)
        # SPREAD: the slices go to different nodes where there are several, not all on the first
        self.actor = actor_cls.options(scheduling_strategy="SPREAD").remote(list(env_fns))
        self.pending: list[tuple[tuple[str, Any], Any]] = []
        self.attrs: dict[str, list[Any]] = {}
        self.seeds: list[int | None] = [None] * self.size
        self.last: tuple[np.ndarray, dict[str, Any]] | None = None
        self.restarts = 0
        self.incarnation: str | None = None
        self.unreset = False
        """The actor was restarted and its envs not reset since: the next step resets them."""

    def send(self, message: tuple[str, Any]) -> None:
        command, payload = message
        if command == "set_attr":
            self.attrs[payload[0]] = payload[1]
        elif command == "reset":
            self.seeds = list(payload["seeds"])
        if command == "step" and self.unreset:
            # the actor was restarted since the learner last saw its envs: instead of this step,
            # reset them and answer as if their episodes were truncated (`_truncated_here`)
            self.unreset = False
            message, command, payload = ("lost_step", None), "reset", self._restart_reset()
        self.pending.append((message, self.actor.run_here.remote(command, payload)))

    def recv(self) -> tuple[str, Any]:
        message, ref = self.pending.pop(0)
        try:
            incarnation, reply = self.ray.get(ref)
        except (self.ray.exceptions.RayActorError, self.ray.exceptions.ActorUnavailableError) as error:
            reply = self._recover(message, error)
        else:
            if self.incarnation not in (None, incarnation):  # delivered to a restarted actor
                reply = self._recover(message, RuntimeError("answered by a restarted actor"))
            elif message[0] == "lost_step" and reply[0] == "ok":
                reply = "ok", self._truncated_here(*reply[1])
            self.incarnation = incarnation
        status, value = reply
        if status == "ok" and message[0] in ("step", "lost_step"):
            self.last = (value[0], value[4])
        elif status == "ok" and message[0] == "reset":
            self.last = value
        return reply

    def _call(self, command: str, payload: Any) -> tuple[str, Any]:
        """A command to the restarted actor. While Ray is still bringing it up, calls fail with
        `ActorUnavailableError` (not executed): retried for up to `RESTART_WAIT_S`."""
        deadline = time.monotonic() + RESTART_WAIT_S
        while True:
            try:
                self.incarnation, reply = self.ray.get(self.actor.run_here.remote(command, payload))
                return reply
            except self.ray.exceptions.ActorUnavailableError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)

    def _restart_reset(self) -> dict[str, Any]:
        """The reset of a restarted actor's envs: their first seeds, moved on by the restart count."""
        return {"seeds": [None if s is None else s + self.restarts * RESTART_SEED_STRIDE for s in self.seeds],
                "options": None}

    def _recover(self, message: tuple[str, Any], error: Exception) -> tuple[str, Any]:
        """The reply to `message` from the restarted actor, whose envs are new: it gets the
        attributes set so far, then a step is answered with a reset (`_truncated_here`); any other
        command is re-sent, and the next step becomes that reset."""
        command, payload = message
        if command == "close":
            return "ok", None
        self.restarts += 1
        if self.restarts > self.max_restarts:
            raise RuntimeError(f"the Ray worker of envs {self.first}..{self.first + self.size - 1} died "
                               f"{self.restarts} times (runtime.ray_max_restarts = {self.max_restarts})") from error
        for name, values in self.attrs.items():
            self._check(self._call("set_attr", (name, values)))
        if self.on_restart is not None:
            self.on_restart({"kind": "worker_restart", "envs": [self.first, self.first + self.size - 1],
                             "restart": self.restarts, "during": command, "error": type(error).__name__})
        if command in ("step", "lost_step"):
            self.unreset = False
            return "ok", self._truncated_here(*self._check(self._call("reset", self._restart_reset())))
        self.unreset = command != "reset"
        return self._call(command, payload)

    @staticmethod
    def _check(reply: tuple[str, Any]) -> Any:
        status, value = reply
        if status == "error":
            raise RuntimeError(f"a vector-env worker failed after its restart:\n{value}")
        return value

    def _truncated_here(self, obs: np.ndarray, infos: dict[str, Any]) -> tuple:
        """A step's reply in which every env of the slice was truncated at its last observation
        (SAME_STEP layout: the new episodes' first observations, the old ones' in `final_obs`)."""
        if self.last is None:
            raise RuntimeError("a Ray worker died before its envs were ever reset")
        last_obs, last_infos = self.last
        final_obs = np.empty(self.size, dtype=object)
        for i, row in enumerate(last_obs):
            final_obs[i] = row
        mask = np.ones(self.size, dtype=bool)
        final_info = {k: v for k, v in last_infos.items() if k not in _FINAL_KEYS}
        infos = {**infos, "final_obs": final_obs, "_final_obs": mask, "final_info": final_info, "_final_info": mask}
        zeros = np.zeros(self.size, dtype=bool)
        return obs, np.zeros(self.size), zeros, ~zeros, infos

    def close(self) -> None:
        self.ray.kill(self.actor)


def ray_vector_env(env_fns: Sequence[EnvFn], workers: int | None, address: str | None, max_restarts: int,
                   on_restart: RestartCallback | None = None) -> ShardedVectorEnv:
    """`len(env_fns)` envs in `workers` slices (default: one per CPU of the Ray cluster), the
    last stepped by this process, each other one by a Ray actor."""
    ray = connect(address)
    slices = workers or int(ray.cluster_resources().get("CPU", os.cpu_count() or 1))
    return ShardedVectorEnv(
        env_fns, slices, remote=lambda fns, first: _RayShard(ray, fns, first, max_restarts, on_restart)
    )
