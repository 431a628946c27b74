"""The run directory: the one place that knows the files a run writes, how a checkpoint is saved
and read, and how a run's agent is rebuilt.

    runs/pick-place-seed0/
      config.json      what the run was started with (curriculum, agent, tasks, seed, steps)
      checkpoint.pt    the latest state (agent, scheduler): what `--resume` continues from
      final.pt         the policy at the end of the budget (no optimizer state, no scheduler)
      final_eval.json  the evaluation of the final policy that `taskforge train` prints
      sweep_eval.json  in a sweep's trial: the final policy under each of the sweep's test conditions
      metrics.jsonl    one record per PPO update; events.jsonl: promotions, warnings
      demos.npz        generated demonstrations; dagger.npz: DAgger's labelled states
      tensorboard/     the same numbers for watching live

Training writes it, evaluation, plotting and the benchmarks read it; they all go through
`RunDir`, so a file name is spelled once. Checkpoints are written atomically (`taskforge.atomic`)
and read with `torch.load(weights_only=True)`: a checkpoint someone sent you can hold tensors,
numbers, strings and containers of them, never code to run. (Agents and the scheduler keep
their state in exactly those, so no numpy type needs allow-listing.)
"""

from __future__ import annotations

import json
import pickle
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from taskforge.agents import Agent, agent_observation_space, make_agent
from taskforge.agents.runtime import device_available, flush_denormals
from taskforge.atomic import atomic_write
from taskforge.envs import PhaseShapes, probe_phases
from taskforge.spec import AgentSpec, SpecError, TaskSpec


class RunDir:
    """Paths of a run's files. Nothing is created until something is written."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"RunDir({str(self.path)!r})"

    def __str__(self) -> str:
        return str(self.path)

    config = property(lambda self: self.path / "config.json")
    checkpoint = property(lambda self: self.path / "checkpoint.pt")
    final = property(lambda self: self.path / "final.pt")
    final_eval = property(lambda self: self.path / "final_eval.json")
    sweep_eval = property(lambda self: self.path / "sweep_eval.json")
    metrics = property(lambda self: self.path / "metrics.jsonl")
    events = property(lambda self: self.path / "events.jsonl")
    demos = property(lambda self: self.path / "demos.npz")
    dagger = property(lambda self: self.path / "dagger.npz")
    tensorboard = property(lambda self: self.path / "tensorboard")
    curves = property(lambda self: self.path / "curves.png")

    def policy_checkpoint(self) -> Path:
        """What to evaluate: the final policy, else the latest checkpoint of an unfinished run."""
        for path in (self.final, self.checkpoint):
            if path.is_file():
                return path
        raise SpecError.single(self.path, "", f"no {self.final.name} or {self.checkpoint.name} in this run directory")

    def steps_done(self) -> int:
        """How far the run got: its checkpoint's step, else its last metrics record's (a finished
        benchmark run is kept with its metrics but without its checkpoint); 0 for a new run."""
        if self.checkpoint.is_file():
            return int(load_checkpoint(self.checkpoint)["agent"]["global_step"])
        records = read_jsonl(self.metrics)
        return int(records[-1]["step"]) if records else 0

    def read_metrics(self) -> list[dict[str, Any]]:
        return read_jsonl(self.metrics)

    def read_events(self) -> list[dict[str, Any]]:
        """Curriculum moves (promotions, demotions, finish: they carry `to_stage`) and warnings."""
        return read_jsonl(self.events)

    def stage_changes(self) -> list[tuple[int, str]]:
        """(step, stage moved to) of every promotion and demotion."""
        return [(e["step"], e["to_stage"]) for e in self.read_events() if "to_stage" in e]

    def remove_stale_temporaries(self) -> None:
        """Half-written files of a process killed mid-save (see `taskforge.atomic`)."""
        for stale in self.path.glob(".*.tmp"):
            stale.unlink()


# ------------------------------------------------------------------------------ checkpoints

def save_checkpoint(state: dict[str, Any], path: Path) -> None:
    """Atomic: a kill or a full disk leaves the previous checkpoint as it was. A failed write is a
    `SpecError` naming the file (the run keeps its previous checkpoint)."""
    try:
        atomic_write(path, lambda f: torch.save(state, f))
    except OSError as exc:
        raise SpecError.single(path, "", f"could not write the checkpoint ({exc.strerror or exc}); "
                               "the previous checkpoint, if any, is intact") from None


def load_checkpoint(path: Path) -> dict[str, Any]:
    """A checkpoint's state, loaded without running any code (`weights_only=True`): a file that
    needs more (a pickled object) or is truncated is refused with a `SpecError` naming it."""
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise SpecError.single(path, "", "no such checkpoint file") from None
    except pickle.UnpicklingError as exc:
        # torch names what it refused on a line of its own, e.g. "Trying to load unsupported GLOBAL posix.system ..."
        found = re.search(r"GLOBAL (\S+)", str(exc))
        what = f" (it would call {found.group(1)})" if found else ""
        raise SpecError.single(path, "", f"refused: it holds more than tensors, numbers and containers{what}; "
                               "taskforge loads checkpoints without running code") from None
    except Exception as exc:  # a damaged file fails anywhere in the unpickler, with any error
        raise SpecError.single(path, "", f"not a readable checkpoint (truncated or corrupt: {exc.__class__.__name__})") from None
    if not isinstance(state, dict) or "agent" not in state or "config" not in state:
        raise SpecError.single(path, "", "not a taskforge checkpoint (expected a state with 'agent' and 'config')")
    return state


# ------------------------------------------------------------------------------ JSON files


def save_json(data: Any, path: Path) -> None:
    atomic_write(path, lambda f: f.write((json.dumps(data, indent=2, default=str) + "\n").encode()))


def read_jsonl(path: Path) -> list[dict[str, Any]]:
    """Records of a JSONL file; a torn last line (killed mid-write) is skipped."""
    if not path.exists():
        return []
    records = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return records


# ------------------------------------------------------------------------------ agents


def build_agent(
    agent_spec: AgentSpec, phases: Sequence[tuple[TaskSpec, str | Path]], seed: int, where: str | Path, agent_file: str | Path
) -> tuple[Agent, PhaseShapes]:
    """The agent for a curriculum's phases (one policy for all: their shapes must agree). Used to
    start a run and to load one, so both build exactly the same networks."""
    privileged = agent_spec.asymmetric_critic
    if agent_spec.algo == "mpc" and not device_available(agent_spec.planning.device):
        raise SpecError.single(agent_file, "mpc.device", f"{agent_spec.planning.device!r}, but torch {torch.__version__} finds no such "
                               f"device here ({torch.cuda.device_count()} CUDA devices); set it to cpu or to a CUDA device present")
    shapes = probe_phases(phases, privileged, where)
    if privileged and shapes.privileged_size == 0:
        raise SpecError.single(agent_file, "asymmetric_critic", "the curriculum's backends expose no privileged features; set it to false")
    obs_space = agent_observation_space(agent_spec, shapes.observation_space, shapes.action_space)
    return make_agent(agent_spec, obs_space, shapes.action_space, shapes.privileged_size, seed), shapes


@dataclass
class LoadedRun:
    """A run's policy, brought back from a checkpoint with the config stored beside it (tasks
    included, so the original YAML files need not exist any more)."""

    agent: Agent
    config: dict[str, Any]
    shapes: PhaseShapes
    checkpoint: Path

    @property
    def phases(self) -> list[tuple[TaskSpec, str, list[str]]]:
        """(task, task file, stages) of every phase."""
        return [(TaskSpec.model_validate(p["task"]), p["task_file"], p["stages"]) for p in self.config["phases"]]


def policy_file(path: str | Path) -> Path:
    """The checkpoint a run directory (its final policy, else its latest checkpoint) or a
    checkpoint file names; a `SpecError` naming `path` when it is neither or holds no policy."""
    path = Path(path)
    if path.is_dir():
        return RunDir(path).policy_checkpoint()
    if path.is_file():
        return path
    raise SpecError.single(path, "", "no such run directory or checkpoint file")


def load_run(path: str | Path) -> LoadedRun:
    """A run directory (its final policy, else its latest checkpoint) or a checkpoint file."""
    checkpoint = policy_file(path)
    state = load_checkpoint(checkpoint)
    config = state["config"]
    try:
        agent_spec = AgentSpec.model_validate(config["agent"])
        phases = [(TaskSpec.model_validate(p["task"]), p["task_file"]) for p in config["phases"]]
    except (KeyError, TypeError, ValueError) as exc:
        raise SpecError.single(checkpoint, "config", f"not the config of a taskforge run ({exc.__class__.__name__})") from None
    if agent_spec.algo == "mpc" and not device_available(agent_spec.planning.device):
        # a policy trained on a GPU is still evaluated (rendered, fine-tuned from) where there is none
        agent_spec = agent_spec.with_planning(device="cpu")
    flush_denormals()  # before the agent's first tensor op (an evaluation plans as slowly as training)
    agent, shapes = build_agent(agent_spec, phases, config["seed"], checkpoint, checkpoint)
    agent.load_state_dict(state["agent"])
    return LoadedRun(agent, config, shapes, checkpoint)
