"""The Gymnasium env on the real Meta-World simulator."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml
from gymnasium.utils.env_checker import check_env

import taskforge
from taskforge import SpecError
from taskforge.envs import TaskEnv
from taskforge.spec import TaskSpec, load_task_spec
from tests.conftest import PICK_PLACE, TASKS

STAGES = ["reach", "push", "pick", "place"]


@pytest.fixture(scope="module")
def pick_place_doc() -> dict:
    return yaml.safe_load(PICK_PLACE.read_text())


def env_from(doc: dict, **kwargs) -> TaskEnv:
    return TaskEnv(TaskSpec.model_validate(doc), "test.yaml", **kwargs)


@pytest.mark.parametrize("stage", STAGES)
def test_check_env_passes_for_each_stage(stage):
    env = taskforge.make(PICK_PLACE, stage=stage, seed=0)
    check_env(env, skip_render_check=True)
    env.close()


def test_info_carries_stage_success_terms_and_native_success():
    env = taskforge.make(PICK_PLACE, stage="place", seed=0, native=True)
    env.reset()
    _, reward, _, _, info = env.step(env.action_space.sample())
    assert set(info["reward_terms"]) == {"tcp_to_object", "grasp", "lift", "object_to_goal", "stage_success", "action_l2"}
    weights = {r.term: r.weight for r in env.task.stage("place").rewards}
    assert reward == pytest.approx(sum(weights[k] * v for k, v in info["reward_terms"].items()))
    assert info["success"] in (True, False) and info["native_success"] in (0.0, 1.0)
    assert info["stage"] == "place" and info["task"] == "pick-place-v3"


def test_same_seed_same_trajectory_and_different_seed_differs():
    def rollout(seed: int) -> np.ndarray:
        env = taskforge.make(PICK_PLACE, stage="pick", seed=seed)
        env.action_space.seed(seed)
        obs = [env.reset()[0]]
        for _ in range(20):
            obs.append(env.step(env.action_space.sample())[0])
        return np.array(obs)

    a, b, c = rollout(3), rollout(3), rollout(4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_hidden_and_observable_goal_differ_only_in_goal_slice(pick_place_doc):
    hidden, observable = copy.deepcopy(pick_place_doc), copy.deepcopy(pick_place_doc)
    hidden["goals"]["observable"], observable["goals"]["observable"] = False, True
    envs = [env_from(hidden, stage="pick", seed=5), env_from(observable, stage="pick", seed=5)]
    obs = [e.reset()[0] for e in envs]
    action = np.array([0.3, -0.2, 0.1, 0.5], dtype=np.float32)
    for _ in range(5):
        obs = [e.step(action)[0] for e in envs]
    goal = envs[0].backend.goal_slice
    hidden, shown = obs
    goal_minus_object = np.r_[len(shown) - 3:len(shown)]  # observation.relative_positions' last 3 floats
    np.testing.assert_array_equal(np.delete(hidden, np.r_[goal, goal_minus_object]), np.delete(shown, np.r_[goal, goal_minus_object]))
    assert np.all(hidden[goal] == 0.0) and np.all(hidden[goal_minus_object] == 0.0)
    true_goal = envs[1].features()["goal_pos"]
    assert np.abs(shown[goal] - true_goal).max() < 0.02  # the goal, plus observation noise


def test_reach_stage_success_flips_when_the_gripper_reaches_the_object(pick_place_doc):
    doc = copy.deepcopy(pick_place_doc)
    doc.pop("randomization")
    env = env_from(doc, stage="reach", seed=0)
    env.reset()
    successes = []
    for _ in range(120):
        f = env.features()
        action = np.append(np.clip((f["object_pos"] - f["tcp_pos"]) * 20.0, -1, 1), -1.0)
        _, _, _, _, info = env.step(action)
        successes.append(info["success"])
        if info["success"]:
            break
    assert not successes[0]
    assert successes[-1], "a proportional controller should reach the puck"
    assert env.features()["tcp_to_object_distance"] < 0.03


def test_hold_steps_counts_success_only_after_the_condition_held_that_long(pick_place_doc):
    doc = copy.deepcopy(pick_place_doc)
    doc.pop("randomization")
    doc["stages"][0]["success"]["hold_steps"] = 5
    doc["stages"][0]["terminate_on_success"] = True
    doc["stages"][0]["rewards"].append({"term": "stage_success", "weight": 1.0})
    env = env_from(doc, stage="reach", seed=0)
    env.reset()
    held, history = 0, []
    for _ in range(120):
        f = env.features()
        _, _, terminated, _, info = env.step(np.append(np.clip((f["object_pos"] - f["tcp_pos"]) * 20.0, -1, 1), -1.0))
        held = held + 1 if env.features()["tcp_to_object_distance"] < 0.03 else 0  # the condition, by hand
        history.append((held, info["success"], info["reward_terms"]["stage_success"], terminated))
        if terminated:
            break
    assert history[-1] == (5, True, 1.0, True)  # ends on the 5th step in a row, paid there
    assert all(not success and not paid and not end for h, success, paid, end in history[:-1])
    assert any(0 < h < 5 for h, *_ in history)  # the condition held earlier without counting


def test_tcp_to_object_progress_pays_the_approach_once_with_the_goal_hidden(pick_place_doc):
    """The object's progress term does not depend on the goal, so a task that hides its goal may
    be paid it; over an approach and a retreat it pays start distance - closest distance."""
    doc = copy.deepcopy(pick_place_doc)
    doc.pop("randomization")
    doc["goals"]["observable"] = False
    doc["observation"] = {"features": ["tcp_pos", "object_pos"]}
    doc["stages"][0]["rewards"] = [{"term": "tcp_to_object_progress", "weight": 1.0}]
    env = env_from(doc, stage="reach", seed=0)
    env.reset()
    start = closest = env.features()["tcp_to_object_distance"]
    paid = []
    for k in range(60):
        f = env.features()
        toward = np.clip((f["object_pos"] - f["tcp_pos"]) * 20.0, -1, 1)
        _, reward, *_ = env.step(np.append(toward if k < 40 else -toward, -1.0))
        paid.append(reward)
        closest = min(closest, env.features()["tcp_to_object_distance"])
    assert all(r == 0.0 for r in paid[45:])  # moving away never pays
    assert sum(paid) == pytest.approx(start - closest, abs=1e-6)


def test_push_stage_moves_goal_to_the_table_and_closer(pick_place_doc):
    env = taskforge.make(PICK_PLACE, stage="push", seed=2)
    env.reset(options={"goal_index": 4})
    f_push = env.features()
    env.reset(options={"stage": "place", "goal_index": 4})
    f_place = env.features()
    rest = f_push["object_pos"]
    assert f_push["goal_pos"][2] == pytest.approx(rest[2], abs=1e-6)
    d_push = np.linalg.norm(f_push["goal_pos"][:2] - rest[:2])
    d_place = np.linalg.norm(f_place["goal_pos"][:2] - f_place["object_pos"][:2])
    assert d_push == pytest.approx(0.5 * d_place, rel=1e-6)


def test_height_scale_keeps_part_of_the_drawn_height_around_the_stage_height(pick_place_doc):
    def goal(override: dict | None) -> np.ndarray:
        doc = copy.deepcopy(pick_place_doc)
        if override is not None:
            doc["stages"][-1]["goal"] = override
        env = env_from(doc, stage="place", seed=3)
        env.reset(options={"goal_index": 7})
        return env.features()["goal_pos"].copy()

    drawn, plane, half = goal(None), goal({"height": 0.15}), goal({"height": 0.15, "height_scale": 0.5})
    assert abs(drawn[2] - 0.15) > 0.01  # the check below would pass trivially on the plane itself
    assert plane[2] == pytest.approx(0.15, abs=1e-9)
    assert half[2] == pytest.approx(0.15 + 0.5 * (drawn[2] - 0.15), abs=1e-9)
    np.testing.assert_allclose(half[:2], drawn[:2], atol=1e-9)  # the horizontal goal is left alone


def test_test_split_uses_held_out_goals():
    def goals(split: str) -> set[tuple]:
        env = taskforge.make(PICK_PLACE, stage="place", split=split, seed=0)
        out = set()
        for i in range(5):
            env.reset(options={"goal_index": i})
            out.add(tuple(np.round(env.features()["goal_pos"], 6)))
        return out

    assert goals("train").isdisjoint(goals("test"))


def test_episode_length_follows_the_stage():
    env = taskforge.make(PICK_PLACE, stage="reach", seed=0)
    env.reset()
    steps, truncated = 0, False
    while not truncated:
        *_, truncated, _ = env.step(np.zeros(4, dtype=np.float32))
        steps += 1
    assert steps == 150


def test_privileged_info_has_velocity_goal_and_physics_draws():
    env = taskforge.make(PICK_PLACE, stage="pick", seed=0, privileged=True)
    _, info = env.reset()
    n_draws = env._randomizers["pick-place-v3"].draw_size
    assert info["privileged"].shape == (3 + 3 + n_draws,) and n_draws > 10


def test_mt10_task_set_appends_one_hot_and_can_pin_a_sub_task():
    env = taskforge.make(TASKS / "metaworld/mt10.yaml", seed=0, task="reach-v3")
    obs, info = env.reset()
    names = env.backend.task_names
    assert len(names) == 10 and obs.shape == (39 + 10,)
    assert obs[39 + names.index("reach-v3")] == 1.0 and obs[39:].sum() == 1.0
    assert info["task"] == "reach-v3"
    check_env(env, skip_render_check=True)


def test_bad_stage_or_split_is_a_spec_error():
    with pytest.raises(SpecError, match="no stage 'pik'.*did you mean 'pick'"):
        taskforge.make(PICK_PLACE, stage="pik")
    with pytest.raises(SpecError, match="unknown split"):
        taskforge.make(PICK_PLACE, split="validation")


@pytest.mark.parametrize("object_start", ["goal_set", "random"])
def test_scripted_pick_place_grasps_lifts_and_places(pick_place_doc, object_start):
    """Meta-World's own scripted policy, run through our env: `object_grasped` agrees with
    Meta-World's contact test on every step, and pick then place success flip on. With a random
    object start this also checks Meta-World's internals moved with the object (its policy
    reads the observation, its success flag its own state)."""
    from metaworld.policies.sawyer_pick_place_v3_policy import SawyerPickPlaceV3Policy

    doc = copy.deepcopy(pick_place_doc)
    doc["goals"]["observable"] = True  # the scripted policy reads the goal from the observation
    doc["randomization"] = {"object_start": object_start}
    env = env_from(doc, stage="place", seed=1, native=True)  # Meta-World's own success flag too
    policy = SawyerPickPlaceV3Policy()
    pick = env.stages["pick"]
    obs, _ = env.reset()
    picked = placed = False
    for _ in range(300):
        obs, _, _, _, info = env.step(policy.get_action(obs[:39].astype(np.float64)))  # its own 39 floats
        f = env.features()
        assert f["object_grasped"] == float(env.backend._active.touching_main_object)
        picked |= pick.success(f)
        if info["success"]:
            placed = True
            break
    assert picked and placed and info["native_success"] == 1.0


OBJECT_START_TASKS = {
    # task file: (object region low, high in x, y; minimum horizontal distance to the goal)
    TASKS / "metaworld" / "reach.yaml": ((-0.1, 0.6), (0.1, 0.7), 0.15),
    TASKS / "xarm7" / "pick_place.yaml": ((0.30, -0.25), (0.60, 0.25), 0.10),
}


@pytest.mark.parametrize("path", OBJECT_START_TASKS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_random_object_start_is_independent_of_the_goal_repeated_within_a_trial_and_seeded(path):
    low, high, min_dist = OBJECT_START_TASKS[path]
    doc = yaml.safe_load(path.read_text())
    doc.pop("randomization", None)

    def starts(object_start: str, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
        doc["randomization"] = {"object_start": object_start}
        env = env_from(doc, stage=doc["stages"][0]["name"], seed=seed)
        out = []
        for options in [{"goal_index": 3}, {"goal_index": 3}, {"same_task": True}, {"goal_index": 3}]:
            obs, _ = env.reset(options=options)
            f = env.features()
            np.testing.assert_allclose(obs[4:7], f["object_pos"], atol=1e-3)  # observed where it is
            out.append((f["object_pos"].copy(), f["goal_pos"].copy()))
        env.close()
        return out

    fixed = starts("goal_set", 0)
    assert all(np.allclose(o, fixed[0][0], atol=1e-3) for o, _ in fixed)

    drawn = starts("random", 0)
    objects = np.array([o for o, _ in drawn])
    assert all(np.array_equal(g, fixed[0][1]) for _, g in drawn), "the goal stays the goal entry's"
    assert np.linalg.norm(objects[0] - objects[1]) > 1e-3 and np.linalg.norm(objects[1] - objects[3]) > 1e-3
    np.testing.assert_allclose(objects[2], objects[1], atol=1e-6)  # same_task repeats the start
    assert np.all(objects[:, :2] >= np.array(low) - 0.005) and np.all(objects[:, :2] <= np.array(high) + 0.005)
    assert np.all(np.linalg.norm(objects[:, :2] - fixed[0][1][:2], axis=1) >= min_dist - 0.005)
    np.testing.assert_array_equal(objects, np.array([o for o, _ in starts("random", 0)]))
    assert not np.allclose(objects, np.array([o for o, _ in starts("random", 1)]))


FRESH_GOAL_TASKS = {
    # task file: (goal region low, high in x, y; minimum horizontal object-goal distance)
    TASKS / "metaworld" / "push.yaml": ((-0.1, 0.8), (0.1, 0.9), 0.15),
    TASKS / "xarm7" / "pick_place.yaml": ((0.30, -0.25), (0.60, 0.25), 0.10),
}


@pytest.mark.parametrize("path", FRESH_GOAL_TASKS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_fresh_training_goals_are_new_each_task_seeded_and_leave_the_test_split_alone(path):
    """`goals.train.draw: fresh` draws goal and object per task instance on the train split
    (repeated by same_task, the same for the same seed); the test split keeps its fixed set."""
    low, high, min_dist = FRESH_GOAL_TASKS[path]
    doc = yaml.safe_load(path.read_text())
    doc.pop("randomization", None)
    stage = doc["stages"][0]["name"]

    def tasks(draw: str, split: str, seed: int) -> np.ndarray:
        doc["goals"] = {**doc.get("goals", {}), "train": {"count": 50, "draw": draw}}
        env = env_from(doc, stage=stage, seed=seed, split=split)
        out = []
        for options in [{"goal_index": 3}, {"goal_index": 3}, {"same_task": True}, {"goal_index": 7}]:
            env.reset(options=options)
            f = env.features()
            out.append(np.concatenate([f["object_pos"], f["goal_pos"]]))
        env.close()
        return np.array(out)

    fixed = tasks("set", "train", 0)
    fresh = tasks("fresh", "train", 0)
    objects, goals = fresh[:, :3], fresh[:, 3:]
    assert np.linalg.norm(fresh[0] - fresh[1]) > 1e-3 and np.linalg.norm(fresh[1] - fresh[3]) > 1e-3, "a new task each episode"
    np.testing.assert_allclose(fresh[2], fresh[1], atol=1e-6)  # same_task repeats the drawn task
    assert not any(np.allclose(g, fixed[0, 3:], atol=1e-3) or np.allclose(g, fixed[3, 3:], atol=1e-3) for g in goals)
    assert np.all(goals[:, :2] >= np.array(low) - 1e-6) and np.all(goals[:, :2] <= np.array(high) + 1e-6)
    assert np.all(np.linalg.norm(objects[:, :2] - goals[:, :2], axis=1) >= min_dist - 0.005)
    np.testing.assert_array_equal(fresh, tasks("fresh", "train", 0))
    assert not np.allclose(fresh, tasks("fresh", "train", 1))
    np.testing.assert_array_equal(tasks("fresh", "test", 0), tasks("set", "test", 0))  # held-out goals unchanged


def test_fresh_training_goals_on_xarm7_stay_in_the_train_cells():
    """The checkerboard gap between train and held-out goals survives fresh draws."""
    from taskforge.backends.xarm7_scene import fresh_train_entry, make_goal_sets
    from taskforge.spec.backends import XArm7BackendSpec

    spec = XArm7BackendSpec.model_validate(yaml.safe_load((TASKS / "xarm7" / "pick_place.yaml").read_text())["backend"])
    _, test = make_goal_sets(spec, 0, 50, 50)
    rng = np.random.default_rng(0)
    fresh = np.array([fresh_train_entry(spec, rng).goals[0] for _ in range(200)])
    cell = np.floor(fresh / spec.goal_split.cell).sum(axis=1).astype(int)
    assert np.all(cell % 2 == 0), "every fresh goal in a train (even) cell"
    gap = np.linalg.norm(fresh[:, None, :] - test.goals[None], axis=2).min()
    assert gap >= 2 * spec.goal_split.margin - 1e-9


def test_random_object_start_is_refused_where_there_is_no_object_to_place(tmp_path):
    from taskforge import load_task

    doc = yaml.safe_load((TASKS / "metaworld" / "reach.yaml").read_text())
    doc["backend"] = {"type": "metaworld", "env": "door-open-v3"}
    doc["randomization"] = {"object_start": "random"}
    path = tmp_path / "door.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(SpecError, match=r"door\.yaml.*randomization\.object_start.*door-open-v3"):
        load_task(path)
    doc["randomization"] = {"object_start": "anywhere"}
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(SpecError, match=r"randomization\.object_start.*goal_set.*random"):
        load_task(path)
    doc["randomization"] = {}
    doc["goals"] = {"train": {"draw": "fresh"}}
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(SpecError, match=r"door\.yaml.*goals\.train\.draw.*door-open-v3.*expected 'set'"):
        load_task(path)
    doc["goals"] = {"test": {"draw": "fresh"}}  # held-out goals are always a fixed set
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(SpecError, match=r"goals\.test\.draw"):
        load_task(path)


def test_ml1_goal_cache_on_disk_round_trips_and_survives_corruption(tmp_path, monkeypatch):
    from taskforge.backends.metaworld import ml1_goals

    monkeypatch.setenv("TASKFORGE_CACHE", str(tmp_path))
    ml1_goals.cache_clear()
    first = ml1_goals("reach-v3", 7)
    (cached,) = tmp_path.glob("ml1-*-reach-v3-seed7.pkl")
    ml1_goals.cache_clear()
    assert [t.data for t in ml1_goals("reach-v3", 7)[1]] == [t.data for t in first[1]]
    cached.write_bytes(b"torn")
    ml1_goals.cache_clear()
    assert [t.data for t in ml1_goals("reach-v3", 7)[0]] == [t.data for t in first[0]]
    ml1_goals.cache_clear()


@pytest.mark.parametrize("task_file", [PICK_PLACE, TASKS / "xarm7/pick_place.yaml"])
def test_relative_positions_append_object_minus_tool_and_goal_minus_object(task_file):
    doc = yaml.safe_load(task_file.read_text())
    doc["randomization"] = {}  # no noise: the appended floats are exact
    doc["observation"] = {"relative_positions": False}
    plain = env_from(doc, stage="place")
    doc["observation"] = {"relative_positions": True}
    env = env_from(doc, stage="place")
    assert env.observation_space.shape[0] == plain.observation_space.shape[0] + 6
    obs, _ = env.reset(seed=0)
    base, _ = plain.reset(seed=0)
    np.testing.assert_allclose(obs[:-6], base, atol=1e-6)  # the backend's observation is unchanged
    for _ in range(5):
        obs = env.step(env.action_space.sample())[0]
    f = env.features()
    np.testing.assert_allclose(obs[-6:-3], f["object_pos"] - f["tcp_pos"], atol=1e-5)
    np.testing.assert_allclose(obs[-3:], f["goal_pos"] - f["object_pos"], atol=1e-5)


def test_relative_positions_hide_the_goal_with_it(pick_place_doc):
    doc = copy.deepcopy(pick_place_doc)
    doc["goals"]["observable"] = False
    doc["observation"] = {"relative_positions": True}
    env = env_from(doc, stage="place")
    obs, _ = env.reset(seed=0)
    assert np.all(obs[-3:] == 0.0) and np.any(obs[-6:-3] != 0.0)


def test_relative_positions_need_the_position_features(tmp_path):
    doc = {"name": "pendulum", "backend": {"type": "gymnasium", "env": "Pendulum-v1"},
           "stages": [{"name": "s", "rewards": [{"term": "native"}], "success": {"all": [{"feature": "native_return", "above": 0}]}}],
           "observation": {"relative_positions": True}}
    with pytest.raises(SpecError, match="observation.relative_positions: the gymnasium backend does not provide goal_pos, object_pos, tcp_pos"):
        env_from(doc)


@pytest.mark.parametrize("task_file", [PICK_PLACE, TASKS / "xarm7/pick_place.yaml"])
def test_observation_features_replace_the_backends_observation(task_file):
    doc = yaml.safe_load(task_file.read_text())
    doc["randomization"] = {}  # no noise: the observation is the features exactly
    doc["goals"]["observable"] = False
    doc["observation"] = {"features": ["tcp_pos", "gripper_opening"], "relative_positions": True}
    env = env_from(doc, stage="place")
    assert env.observation_space.shape == (3 + 1 + 6,)
    obs, _ = env.reset(seed=0)
    for _ in range(5):
        obs = env.step(env.action_space.sample())[0]
    f = env.features()
    np.testing.assert_allclose(obs[:3], f["tcp_pos"], atol=1e-5)
    np.testing.assert_allclose(obs[3], f["gripper_opening"], atol=1e-5)
    np.testing.assert_allclose(obs[4:7], f["object_pos"] - f["tcp_pos"], atol=1e-5)
    assert np.all(obs[7:] == 0.0)  # goal - object stays hidden with the goal
    check_env(env, skip_render_check=True)


def test_observation_features_refuse_unknown_names_and_a_hidden_goal(pick_place_doc, tmp_path):
    doc = copy.deepcopy(pick_place_doc)
    doc["observation"] = {"features": ["tcp_pos", "tcp_position"]}
    with pytest.raises(SpecError, match=r"observation.features\[1\]: 'tcp_position' is not a feature .* expected one of .*tcp_pos"):
        env_from(doc)
    doc["goals"]["observable"] = False
    doc["observation"] = {"features": ["tcp_pos", "tcp_to_goal_distance"]}
    with pytest.raises(SpecError, match=r"observation.features\[1\]: 'tcp_to_goal_distance' depends on the goal, which this task hides"):
        env_from(doc)
    for bad, message in (([], "at least one feature"), (["tcp_pos", "tcp_pos"], "listed twice: tcp_pos")):
        doc["observation"] = {"features": bad}
        (tmp_path / "task.yaml").write_text(yaml.safe_dump(doc))
        with pytest.raises(SpecError, match=f"task.yaml: observation.features: .*{message}"):
            load_task_spec(tmp_path / "task.yaml")
