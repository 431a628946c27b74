"""The point-mass backend, the meta-RL testbed: motion, goals on the arc, the held-out split,
the hidden goal and the sparse reward of the shipped task, and its one-line errors."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from taskforge.cli import main
from taskforge.envs import TaskEnv, load_task
from tests.conftest import ROOT

SEMICIRCLE = ROOT / "tasks/point_mass/semicircle.yaml"


def semicircle_env(split: str = "train") -> TaskEnv:
    task = load_task(SEMICIRCLE)
    return TaskEnv(task, SEMICIRCLE, split=split)


def test_goals_lie_on_the_semicircle_and_the_held_out_ones_are_new():
    env = semicircle_env()
    backend = env.unwrapped.backend
    goals = {}
    for split in ("train", "test"):
        goals[split] = []
        for i in range(backend.num_goals(split)):
            env.split = split
            env.reset(options={"goal_index": i})
            goals[split].append(env.features()["goal_pos"][:2])
    assert (len(goals["train"]), len(goals["test"])) == (100, 50)
    for split, points in goals.items():
        points = np.array(points)
        np.testing.assert_allclose(np.linalg.norm(points, axis=1), 1.0)
        assert (points[:, 1] >= 0).all(), f"{split}: a goal below the semicircle's diameter"
        assert np.ptp(np.arctan2(points[:, 1], points[:, 0])) > 2.5  # spread over the arc, not a cluster
    nearest = np.min(np.linalg.norm(np.array(goals["test"])[:, None] - np.array(goals["train"])[None], axis=2), axis=1)
    assert (nearest > 0).all()  # no held-out goal is a train goal
    # the same seed gives everyone the same goals
    again = semicircle_env()
    again.reset(options={"goal_index": 7})
    env.split = "train"
    env.reset(options={"goal_index": 7})
    np.testing.assert_array_equal(again.features()["goal_pos"], env.features()["goal_pos"])


def test_the_point_moves_by_max_step_per_unit_action_and_stays_in_bounds():
    env = semicircle_env()
    env.reset(options={"goal_index": 0})
    env.step(np.array([1.0, -0.5], dtype=np.float32))
    np.testing.assert_allclose(env.features()["tcp_pos"], [0.1, -0.05, 0.0])
    backend = env.unwrapped.backend
    for _ in range(30):  # 3 m to the right and down: clamped at the 2 m bound
        obs, ended = backend.step(np.array([1.0, -1.0]))
    np.testing.assert_allclose(obs[:2], [2.0, -2.0])
    assert not ended  # nothing ends an episode but its time limit


def test_the_goal_is_hidden_and_the_reward_is_paid_only_near_it():
    env = semicircle_env()
    obs, _ = env.reset(options={"goal_index": 3})
    goal = env.features()["goal_pos"][:2]
    assert obs.shape == (4,) and not obs[2:].any()  # the goal's place in the observation is zeroed
    direction = goal / np.linalg.norm(goal)
    rewards, successes = [], []
    for _ in range(10):  # straight at the goal: within 0.2 m after 8 steps
        _, reward, terminated, truncated, info = env.step((direction / np.abs(direction).max()).astype(np.float32))
        rewards.append(reward)
        successes.append(info["success"])
    distance = np.linalg.norm(env.features()["tcp_pos"][:2] - goal)
    assert distance < 0.2
    assert rewards[0] == 0.0 and rewards[-1] == 1.0  # sparse: nothing far away, 1 per step near
    assert successes == [r == 1.0 for r in rewards] and info["episode_success"]
    assert not terminated and not truncated  # the episode runs its 20 steps


def with_stage_rewards(tmp_path, rewards: list[dict]):
    doc = yaml.safe_load(SEMICIRCLE.read_text())
    doc["stages"][0]["rewards"] = rewards
    path = tmp_path / "task.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_progress_pays_only_for_beating_the_episode_record(tmp_path):
    path = with_stage_rewards(tmp_path, [{"term": "tcp_to_goal_progress", "weight": 10.0}])
    env = TaskEnv(load_task(path), path)
    for episode in range(2):  # the record starts again with every episode, as in an RL² trial
        env.reset(options={"goal_index": 3} if episode == 0 else {"same_task": True})
        goal = env.features()["goal_pos"][:2]
        start = np.linalg.norm(goal)
        toward = (goal / np.abs(goal).max()).astype(np.float32)  # a full step along the larger axis
        paid, distances = [], []
        for action in [toward] * 3 + [-toward] * 2 + [toward] * 3:  # in, back out, in again past the record
            _, reward, *_, info = env.step(action)
            paid.append(reward)
            distances.append(np.linalg.norm(env.features()["tcp_pos"][:2] - goal))
        assert all(r > 0 for r in paid[:3]) and paid[3:6] == [0.0] * 3  # out and back up to the record: nothing
        assert paid[6] == 0.0 or distances[6] < min(distances[:6])
        assert paid[7] > 0 and info["reward_terms"]["tcp_to_goal_progress"] == pytest.approx(paid[7] / 10.0)
        assert sum(paid) == pytest.approx(10.0 * (start - min(distances)))  # the episode's sum: start - closest


def test_a_progress_term_needs_its_distance_from_the_backend(tmp_path, capsys):
    path = with_stage_rewards(tmp_path, [{"term": "object_to_goal_progress", "weight": 1.0}])
    assert main(["validate", "--kind", "task", str(path)]) == 2
    (line,) = [line for line in capsys.readouterr().err.splitlines() if line]
    assert line.startswith(f"error: {path}: stages[0].rewards[0].term: term 'object_to_goal_progress' reads object_to_goal_progress"), line


def test_distance_scale_brings_the_goal_towards_the_start(tmp_path):
    doc = yaml.safe_load(SEMICIRCLE.read_text())
    doc["stages"][0]["goal"] = {"distance_scale": 0.5}
    path = tmp_path / "near.yaml"
    path.write_text(yaml.safe_dump(doc))
    near = TaskEnv(load_task(path), path)
    near.reset(options={"goal_index": 5})
    far = semicircle_env()
    far.reset(options={"goal_index": 5})
    np.testing.assert_allclose(near.features()["goal_pos"], 0.5 * far.features()["goal_pos"])


@pytest.mark.parametrize(
    "change,field,fragment",
    [
        ({"randomization": {"physics": [{"target": "gravity", "dist": "uniform", "low": 0.9, "high": 1.1}]}},
         "randomization.physics", "needs a MuJoCo backend"),
        ({"randomization": {"object_start": "random"}}, "randomization.object_start", "has no object to place"),
        ({"backend": {"type": "point_mass", "goal_radius": 3.0}}, "backend", "must be < 'bound'"),
        ({"backend": {"type": "point_mass", "goal_arc": [180, 0]}}, "backend", "'goal_arc': low (180) must be <= high (0)"),
    ],
)
def test_bad_point_mass_tasks_are_one_line_errors(change, field, fragment, tmp_path, capsys):
    doc = {**yaml.safe_load(SEMICIRCLE.read_text()), **change}
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert main(["validate", "--kind", "task", str(path)]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line]
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}: {field}"), lines
    assert fragment in lines[0], lines[0]


def test_a_height_override_is_refused(tmp_path, capsys):
    doc = yaml.safe_load(SEMICIRCLE.read_text())
    doc["stages"][0]["goal"] = {"height": 0.2}
    path = tmp_path / "height.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert main(["validate", "--kind", "task", str(path)]) == 2
    (line,) = [line for line in capsys.readouterr().err.splitlines() if line]
    assert line.startswith(f"error: {path}: stages[0].goal.height: a point mass moves in the plane"), line
