"""Workers that play every phase of a curriculum: `PhasedEnv`, and training with replay reaching
back into an earlier phase (a robot variant must not be forgotten when the next one starts)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from taskforge.envs import PhasedEnv, load_task
from taskforge.run import read_jsonl
from taskforge.training import train
from tests.test_training import AGENT, TASK


def two_tasks(folder):
    """Pendulum twice: phase 0 ('swing', episodes of 100 steps, always succeeds) and phase 1
    ('hold', 50 steps, never succeeds): the phase an episode ran shows in its stage and length."""
    first = {**TASK, "name": "pendulum-a", "stages": [{**TASK["stages"][0], "name": "swing"}]}
    second = {**TASK, "name": "pendulum-b", "max_episode_steps": 50, "stages": [{**TASK["stages"][1], "name": "hold"}]}
    paths = []
    for name, doc in (("a.yaml", first), ("b.yaml", second)):
        (folder / name).write_text(yaml.safe_dump(doc))
        paths.append(folder / name)
    return paths


def run_episode(env: PhasedEnv, **options) -> tuple[dict, int]:
    _, info = env.reset(options=options or None)
    steps = 0
    while True:
        _, _, terminated, truncated, info = env.step(env.action_space.sample())
        steps += 1
        if terminated or truncated:
            return info, steps


def test_each_episode_plays_the_phase_its_options_name(tmp_path):
    paths = two_tasks(tmp_path)
    env = PhasedEnv([(load_task(p), p) for p in paths])
    env.reset(seed=0)
    assert env.env.task.name == "pendulum-a"
    info, steps = run_episode(env, phase=1)
    assert (info["phase"], info["stage"], steps) == (1, "hold", 50)
    info, steps = run_episode(env)  # no phase given: the previous episode's phase again
    assert (info["phase"], steps) == (1, 50)
    env.next_episode = {"phase": 0, "replay": True}  # a vectorised trainer's way
    info, steps = run_episode(env)
    assert (info["phase"], info["stage"], info["replay"], steps) == (0, "swing", True, 100)
    with pytest.raises(ValueError, match="no phase 2"):
        env.reset(options={"phase": 2})
    env.close()


def test_a_phase_first_played_late_is_seeded_by_the_first_reset(tmp_path):
    paths = two_tasks(tmp_path)

    def observations(seed: int) -> np.ndarray:
        env = PhasedEnv([(load_task(p), p) for p in paths])
        env.reset(seed=seed)
        run_episode(env)
        obs, _ = env.reset(options={"phase": 1})
        env.close()
        return obs

    assert np.array_equal(observations(3), observations(3))
    assert not np.array_equal(observations(3), observations(4))


def test_replay_in_a_later_phase_plays_the_earlier_phase(tmp_path, capsys):
    paths = two_tasks(tmp_path)
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(AGENT))
    curriculum = {
        "name": "two-phase", "agent": "agent.yaml", "seed": 1, "total_steps": 2000,
        "phases": [{"task": paths[0].name}, {"task": paths[1].name}],
        "promotion": {"threshold": 0.9, "window": 4},
        "replay": {"fraction": 0.5},
        "evaluation": {"every_steps": 10_000, "episodes": 1},
        "checkpoint": {"every_steps": 1000},
    }
    (tmp_path / "cur.yaml").write_text(yaml.safe_dump(curriculum))
    run = train(tmp_path / "cur.yaml", run_dir=tmp_path / "run", progress=False)

    [event] = read_jsonl(run / "events.jsonl")
    assert (event["from_phase"], event["to_phase"]) == (0, 1)
    assert "promote: pendulum-a:swing -> pendulum-b:hold" in capsys.readouterr().err  # which task, not only the stage
    later = [m for m in read_jsonl(run / "metrics.jsonl") if m["step"] > event["step"] + 200]
    assert later and all(m["phase"] == 1 for m in later)
    # after the promotion, phase 1 ('hold') is the current stage and phase 0 ('swing') is replayed
    assert any("success/hold" in m for m in later)
    assert any(m.get("success/swing") == 1.0 for m in later)
