"""The lean Meta-World step (taskforge/backends/metaworld_step.py) against untouched Meta-World:
the same states and observations, bit for bit, while skipping Meta-World's reward."""

import warnings

import mujoco
import numpy as np
import pytest
from metaworld.env_dict import ALL_V3_ENVIRONMENTS
from metaworld.policies import ENV_POLICY_MAP
from scipy.spatial.transform import Rotation

import taskforge
from taskforge.backends.metaworld import ml1_goals
from taskforge.backends.metaworld_step import install_fast_observation, quat_from_matrix, step_without_reward
from tests.conftest import PICK_PLACE, TASKS


def fresh(name: str, seed: int, fast: bool):
    """A Meta-World env reset to a random task drawn from `seed` (Meta-World's own sampler)."""
    env = ALL_V3_ENVIRONMENTS[name]()
    env._partially_observable = False  # taskforge runs Meta-World goal-observable (backend doc)
    env._freeze_rand_vec, env.seeded_rand_vec = False, True
    env._set_task_called = True  # the task is the random vector drawn at reset
    env.max_path_length = 10**9
    if fast:
        install_fast_observation(env)
    env.seed(seed)  # Meta-World's reset ignores its seed argument
    obs, _ = env.reset()
    return env, obs


def on_ml1_goal(name: str, goal: int, fast: bool):
    """A Meta-World env on ML1 train goal `goal`, set up as the backend does (goal observable)."""
    env = ALL_V3_ENVIRONMENTS[name]()
    env._partially_observable = True
    env.set_task(ml1_goals(name, 0)[0][goal])
    env._partially_observable = False
    env.__dict__.pop("sawyer_observation_space", None)
    env.max_path_length = 10**9
    if fast:
        install_fast_observation(env)
    obs, _ = env.reset()
    return env, obs


def test_quaternion_is_scipys_to_the_last_bit():
    rng = np.random.default_rng(0)
    for k in range(2000):
        q = rng.normal(size=4) if k % 2 else np.array([1.0, 0, 0, 0]) + 1e-4 * rng.normal(size=4)  # near identity too
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, q / np.linalg.norm(q))
        np.testing.assert_array_equal(quat_from_matrix(mat.tolist()), Rotation.from_matrix(mat.reshape(3, 3)).as_quat())


@pytest.mark.parametrize("name", sorted(ALL_V3_ENVIRONMENTS))
def test_fast_observation_equals_metaworlds_on_every_v3_env(name):
    """At states reached by random actions, the installed helpers return exactly what Meta-World's
    own class methods return on the same env."""
    env, _ = fresh(name, seed=1, fast=True)
    cls, rng = type(env), np.random.default_rng(2)
    for _ in range(15):
        env.step(rng.uniform(-1, 1, 4))
        np.testing.assert_array_equal(env._get_quat_objects(), cls._get_quat_objects(env))
        prev = env._prev_obs  # frame stacking: the original must not see the fast one's update
        fast = env._get_curr_obs_combined_no_goal()
        np.testing.assert_array_equal(fast, cls._get_curr_obs_combined_no_goal(env))
        env._prev_obs = prev
    env.close()


@pytest.mark.parametrize("name", ["pick-place-v3", "push-v3", "reach-v3", "door-open-v3", "peg-insert-side-v3"])
def test_step_without_reward_reproduces_metaworlds_step(name):
    """Two episodes of 500 steps of Meta-World's scripted policy (with some action noise, so
    states vary): untouched `env.step` on one env, `step_without_reward` on another; positions,
    velocities, mocap and observations equal at every step, grasps included."""
    policy = ENV_POLICY_MAP[name]()
    rng = np.random.default_rng(3)
    for episode in range(2):
        ref, obs_ref = on_ml1_goal(name, episode, fast=False)
        lean, obs = on_ml1_goal(name, episode, fast=True)
        np.testing.assert_array_equal(obs, obs_ref)
        grasped = 0
        for _ in range(500):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "Constant(s) may be too high"
                action = np.clip(policy.get_action(obs_ref) + rng.normal(0, 0.1, 4), -1, 1)
            obs_ref, *_, info = ref.step(action)
            obs = step_without_reward(lean, action)
            np.testing.assert_array_equal(obs, obs_ref)
            np.testing.assert_array_equal(lean.data.qpos, ref.data.qpos)
            np.testing.assert_array_equal(lean.data.qvel, ref.data.qvel)
            np.testing.assert_array_equal(lean.data.mocap_pos, ref.data.mocap_pos)
            grasped += bool(info["grasp_success"])
        if name == "pick-place-v3":
            assert grasped > 50, grasped  # the comparison covered contact-rich states
        ref.close()
        lean.close()


@pytest.mark.parametrize("task_file", [PICK_PLACE, TASKS / "metaworld/push.yaml"])
def test_taskenv_states_are_the_same_with_and_without_metaworlds_reward(task_file):
    """Under the task's full randomisation (physics, noise, latency), the env that skips
    Meta-World's reward and the one that computes it see identical states and observations;
    only the second carries `native_success`."""
    envs = [taskforge.make(task_file, stage="place" if task_file == PICK_PLACE else "push", seed=4, native=native)
            for native in (True, False)]
    assert [e.backend.native for e in envs] == [True, False]
    rng = np.random.default_rng(5)
    obs = [e.reset()[0] for e in envs]
    for _ in range(600):  # more than one episode: resets redraw the physics the same way
        action = rng.uniform(-1, 1, 4).astype(np.float32)
        out = [e.step(action) for e in envs]
        np.testing.assert_array_equal(out[0][0], out[1][0])
        assert out[0][1] == out[1][1]  # the stage's reward
        np.testing.assert_array_equal(envs[0].backend.data.qpos, envs[1].backend.data.qpos)
        np.testing.assert_array_equal(envs[0].backend.data.qvel, envs[1].backend.data.qvel)
        assert "native_success" in out[0][4] and "native_success" not in out[1][4]
        if out[0][2] or out[0][3]:
            obs = [e.reset()[0] for e in envs]
            np.testing.assert_array_equal(*obs)


def test_the_env_computes_metaworlds_reward_only_when_a_stage_reads_it():
    assert not taskforge.make(PICK_PLACE).backend.native  # the stages use taskforge's own terms
    mt10 = taskforge.make(TASKS / "metaworld/mt10.yaml", seed=0)  # Meta-World's own reward and success
    assert mt10.backend.native
    mt10.reset()
    _, reward, *_, info = mt10.step(np.zeros(4, np.float32))
    assert "native_success" in info and reward == pytest.approx(info["reward_terms"]["native"])
