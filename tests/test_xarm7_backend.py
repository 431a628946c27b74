"""The xArm7 backend (`backend: {type: xarm7}`) and its task files, on the real simulator."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml
from gymnasium.utils.env_checker import check_env

import taskforge
from taskforge import SpecError
from taskforge.backends.xarm7 import GOAL_SLICE, OBS_SIZE
from taskforge.backends.xarm7_control import R_DOWN
from taskforge.backends.xarm7_scene import BUILTIN_ROBOT, make_goal_sets
from taskforge.envs.factory import check_task_file
from tests.conftest import TASKS

XARM = TASKS / "xarm7"
PICK_PLACE = XARM / "pick_place.yaml"
YAMLS = sorted(XARM.glob("*.yaml"))
STAGES = ["reach", "push", "pick", "place"]
REFERENCE = Path(__file__).resolve().parents[2] / "shared/reference/ufactory_xarm7/xarm7.xml"


def write_task(tmp_path: Path, backend: dict, name: str = "t", **top) -> Path:
    """A one-stage reach task with this backend block, in tmp_path."""
    task = {
        "name": name,
        "backend": {"type": "xarm7", **backend},
        "stages": [{"name": "reach", "rewards": [{"term": "tcp_to_object"}],
                    "success": {"all": [{"feature": "tcp_to_object_distance", "below": 0.03}]}}],
        **top,
    }
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(task))
    return path


def drive(env, target, grip: float, steps: int, gain: float = 0.5):
    """Scripted Cartesian control: each step moves the controller's TCP target `gain` of the
    way to `target` (a proportional law on the target, which stays stable under the task's
    one-step action latency; the servos and IK then bring the TCP there). Returns the
    features after the last step and whether the stage's success held on any step."""
    backend = env.unwrapped.backend
    success = False
    for _ in range(steps):
        step = gain * (np.asarray(target) - backend.cartesian_target) / backend.spec.control.max_step_m
        _, _, _, _, info = env.step(np.clip(np.r_[step, grip], -1.0, 1.0))
        success |= info["success"]
    return backend.features(), success


# --------------------------------------------------------------------------- files


@pytest.mark.parametrize("path", YAMLS, ids=lambda p: p.name)
def test_every_xarm7_task_file_validates_with_its_compiled_model(path):
    spec = check_task_file(path)  # schema, registries, compiled model, randomisation names
    assert spec.backend.type == "xarm7"


def test_the_required_task_files_exist():
    names = {p.name for p in YAMLS}
    assert {"reach.yaml", "push.yaml", "pick_place.yaml", "pick_place_big_cube.yaml",
            "pick_place_high_goals.yaml", "pick_place_low_table.yaml"} <= names


# --------------------------------------------------------------------------- gymnasium API


@pytest.mark.parametrize("task_file,stage", [(PICK_PLACE, s) for s in STAGES] + [(XARM / "reach_joint.yaml", "reach")])
def test_check_env_passes(task_file, stage):
    env = taskforge.make(task_file, stage=stage, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*infinity")  # the env's unbounded observation Box
        check_env(env, skip_render_check=True)
    env.close()


def test_spaces_timing_and_observation_layout():
    env = taskforge.make(PICK_PLACE, seed=0)
    backend = env.unwrapped.backend
    assert env.action_space.shape == (4,) and env.observation_space.shape == (OBS_SIZE + 6,)  # + relative positions
    assert backend.dt == pytest.approx(0.05) and backend.substeps == 25
    assert backend.model("xarm7").opt.timestep == pytest.approx(0.002)
    assert backend.object_geoms("xarm7") == ["object_geom"]
    assert backend.goal_slice == GOAL_SLICE == slice(11, 14)
    obs = backend.reset("xarm7", "train", 0, taskforge.backends.GoalOverride())
    f = backend.features()
    m, d = backend.model("xarm7"), backend.data
    np.testing.assert_allclose(obs[0:3], f["tcp_pos"])
    assert obs[3] == pytest.approx(1.0) == f["gripper_opening"]  # open at reset
    np.testing.assert_allclose(obs[4:7], f["object_pos"])
    np.testing.assert_allclose(obs[7:11], [1, 0, 0, 0], atol=1e-3)
    np.testing.assert_allclose(obs[11:14], f["goal_pos"])
    np.testing.assert_allclose(obs[14:21], m.key("home").qpos[:7], atol=2e-3)
    np.testing.assert_allclose(d.mocap_pos[0], f["goal_pos"])  # the marker shows the goal
    # pick_place.yaml observes the goal (PPO); its RL² variant hides it, and nothing else.
    shown, _ = env.reset(seed=3, options={"goal_index": 0})
    np.testing.assert_allclose(shown[GOAL_SLICE], env.unwrapped.features()["goal_pos"], atol=0.02)  # plus noise
    meta = taskforge.make(PICK_PLACE.with_name("pick_place_meta.yaml"), seed=0)
    hidden, _ = meta.reset(seed=3, options={"goal_index": 0})
    assert np.all(hidden[GOAL_SLICE] == 0.0)
    meta.close()


def test_timing_from_substeps(tmp_path):
    env = taskforge.make(write_task(tmp_path, {"control": {"frequency_hz": 40, "substeps": 10}}))
    assert env.unwrapped.backend.dt == pytest.approx(0.025)
    assert env.unwrapped.backend.model("xarm7").opt.timestep == pytest.approx(0.0025)


def test_bad_backend_fields_are_one_line_spec_errors(tmp_path):
    cases = {
        "backend.control": {"control": {"frequency_hz": 30}},  # 1/(30*0.002) is not whole
        "backend.pad_geoms.left[0]": {"pad_geoms": {"left": ["left_pad"]}},
        "backend.robot_model": {"robot_model": "missing.xml"},
        "backend.goal_region": {"goal_region": {"x": [0.6, 0.3]}},
    }
    for field, backend in cases.items():
        with pytest.raises(SpecError) as err:
            taskforge.make(write_task(tmp_path, backend))
        assert [i.path for i in err.value.issues] == [field], err.value
    with pytest.raises(SpecError, match="did you mean 'left_finger_pad'"):
        taskforge.make(write_task(tmp_path, {"pad_geoms": {"left": ["left_finger_pd"]}}))


# --------------------------------------------------------------------------- IK and control


def test_ik_reaches_random_reachable_targets_within_2mm():
    env = taskforge.make(PICK_PLACE, seed=0)
    env.reset()
    ik = env.unwrapped.backend.ik
    rng = np.random.default_rng(0)
    for _ in range(20):
        target = rng.uniform([0.30, -0.25, 0.01], [0.60, 0.25, 0.30])
        ik.solve(target, iterations=30)
        assert np.linalg.norm(ik.tcp() - target) < 2e-3
        rot = ik.configuration.data.site_xmat[ik.configuration.model.site("link_tcp").id].reshape(3, 3)
        np.testing.assert_allclose(rot, R_DOWN, atol=0.02)  # pointing straight down


def test_cartesian_actions_bring_the_simulated_tcp_within_2mm():
    env = taskforge.make(XARM / "reach.yaml", seed=1)
    env.reset()
    rng = np.random.default_rng(1)
    for _ in range(4):
        target = rng.uniform([0.30, -0.25, 0.03], [0.60, 0.25, 0.30])
        f, _ = drive(env, target, -1.0, 40)
        assert np.linalg.norm(f["tcp_pos"] - target) < 2e-3
    assert env.unwrapped.backend.ik_ms_per_step > 0


def test_workspace_clamps_the_target(tmp_path):
    env = taskforge.make(write_task(tmp_path, {"table_height": -0.05}), seed=0)
    env.reset()
    f, _ = drive(env, [0.45, 0.0, -1.0], -1.0, 40)  # far below the table
    assert f["tcp_pos"][2] == pytest.approx(-0.05 + 0.005, abs=2e-3)  # workspace z min above the table


def test_joint_mode_moves_joint_targets_and_grip():
    env = taskforge.make(XARM / "reach_joint.yaml", seed=0)
    env.reset()
    backend = env.unwrapped.backend
    assert env.action_space.shape == (8,)
    start = backend.data.ctrl[:7].copy()
    action = np.zeros(8)
    action[0], action[7] = 1.0, 1.0  # joint1 +, close the gripper
    for _ in range(10):
        env.step(action)
    np.testing.assert_allclose(backend.data.ctrl[0] - start[0], 10 * 0.05, atol=1e-9)
    np.testing.assert_allclose(backend.data.ctrl[1:7], start[1:7], atol=1e-9)
    assert backend.data.ctrl[7] == pytest.approx(255.0)
    assert backend.features()["gripper_opening"] < 0.1


# --------------------------------------------------------------------------- grasping


@pytest.mark.parametrize("task_file", ["pick_place.yaml", "pick_place_big_cube.yaml", "pick_place_low_table.yaml"])
def test_scripted_pick_lifts_the_cube_with_randomisation(task_file):
    env = taskforge.make(XARM / task_file, stage="pick", seed=0)
    _, info = env.reset()
    assert not info["success"]
    backend = env.unwrapped.backend
    cube = backend.features()["object_pos"].copy()
    size = backend.model("xarm7").geom_size[backend.model("xarm7").geom("object_geom").id, 2]
    drive(env, cube + [0, 0, 0.10], -1.0, 25)                # above the cube, open
    grasp_at = cube + [0, 0, min(0.01 - size, -0.005)]       # fingertips ~1 cm above the table
    f, _ = drive(env, grasp_at, -1.0, 20)                    # descend
    assert f["object_grasped"] == 0.0 and f["gripper_opening"] > 0.9
    f, _ = drive(env, grasp_at, 1.0, 10)                     # close
    assert f["object_grasped"] == 1.0
    held, success = [], False
    for _ in range(25):                                      # lift, step by step
        f, ok = drive(env, cube + [0, 0, 0.15], 1.0, 1)
        held.append(f["object_grasped"])
        success |= ok
    assert f["object_height"] >= 0.05
    assert all(held), held                                   # grasped on every step of the lift
    assert success and env.unwrapped._ever_success           # the pick stage's condition held
    assert 0.0 < f["gripper_opening"] < 0.9                  # closed on the cube
    assert np.linalg.norm(f["object_velocity"]) < 0.5


def test_scripted_place_reaches_a_held_out_high_goal():
    env = taskforge.make(XARM / "pick_place_high_goals.yaml", stage="place", split="test", seed=1)
    env.reset()
    backend = env.unwrapped.backend
    f = backend.features()
    cube, goal = f["object_pos"].copy(), f["goal_pos"].copy()
    assert goal[2] >= 0.2
    grasp_at = cube - [0, 0, 0.01]
    drive(env, cube + [0, 0, 0.10], -1.0, 25)
    drive(env, grasp_at, -1.0, 20)
    drive(env, grasp_at, 1.0, 10)
    f, success = drive(env, goal - (cube - grasp_at), 1.0, 40)  # carry the cube centre to the goal
    assert f["object_grasped"] == 1.0 and f["native_success"] == 1.0 and success


def test_object_features_follow_the_cube():
    env = taskforge.make(PICK_PLACE, stage="place", seed=0)
    env.reset()
    backend = env.unwrapped.backend
    f = backend.features()
    assert f["object_height"] == pytest.approx(0.0, abs=1e-6)
    assert f["native_reward"] == 0.0 and f["native_return"] == 0.0
    assert f["native_success"] == float(f["object_to_goal_distance"] < 0.05)
    assert f["tcp_to_object_distance"] == pytest.approx(np.linalg.norm(f["tcp_pos"] - f["object_pos"]))
    # Put the cube on the goal: native_success flips.
    d = backend.data
    adr = backend.model("xarm7").joint("object_joint").qposadr[0]
    d.qpos[adr : adr + 3] = f["goal_pos"]
    d.qvel[:] = 0.0
    _, _, _, _, info = env.step(np.zeros(4))
    assert info["native_success"] == 1.0


# --------------------------------------------------------------------------- goals


def test_held_out_test_goals_are_disjoint_from_train_goals():
    env = taskforge.make(PICK_PLACE, seed=0)
    backend = env.unwrapped.backend
    train = np.array([backend.goal_entry("train", i)[1] for i in range(backend.num_goals("train"))])
    test = np.array([backend.goal_entry("test", i)[1] for i in range(backend.num_goals("test"))])
    assert len(train) == len(test) == 50
    gaps = np.linalg.norm(train[:, None, :] - test[None, :, :], axis=2)
    assert gaps.min() >= 2 * backend.spec.goal_split.margin - 1e-12
    # Goals lie in the goal region, cube starts in the object region, at least 10 cm apart.
    region = backend.spec.goal_region
    for goals in (train, test):
        assert np.all((goals[:, 0] >= region.x[0]) & (goals[:, 0] <= region.x[1]))
        assert np.all((goals[:, 2] >= region.z[0]) & (goals[:, 2] <= region.z[1]))
    objects = np.array([backend.goal_entry("train", i)[0] for i in range(50)])
    assert np.all(np.linalg.norm(objects - train[:, :2], axis=1) >= 0.1)
    # The same goal index is the same placement every time, whatever the env's seed or the
    # splits' counts (a larger count appends entries), and goals.seed changes them.
    again = taskforge.make(PICK_PLACE, seed=5).unwrapped.backend
    np.testing.assert_array_equal(again.goal_entry("test", 7)[1], test[7])
    small_train, big_test = make_goal_sets(backend.spec, 0, 10, 500)
    np.testing.assert_array_equal(small_train.goals, train[:10] - [0, 0, backend.spec.table_height])
    np.testing.assert_array_equal(big_test.goals[:50, :2], test[:, :2])
    assert not np.array_equal(make_goal_sets(backend.spec, 1, 10, 10)[0].goals, small_train.goals)


def test_push_goals_on_the_table_are_held_out_in_the_plane():
    backend = taskforge.make(XARM / "push.yaml", seed=0).unwrapped.backend
    train, test = make_goal_sets(backend.spec, 0, 500, 500)
    assert np.all(train.goals[:, 2] == 0.0) and np.all(test.goals[:, 2] == 0.0)
    gaps = np.linalg.norm(train.goals[:, None, :2] - test.goals[None, :, :2], axis=2)
    assert gaps.min() >= 2 * backend.spec.goal_split.margin - 1e-12


def test_test_split_resets_to_test_goals():
    env = taskforge.make(PICK_PLACE, stage="place", split="test", seed=0)
    backend = env.unwrapped.backend
    env.reset(options={"goal_index": 4})
    obj, goal = backend.goal_entry("test", 4)
    np.testing.assert_allclose(backend.features()["goal_pos"], goal)
    np.testing.assert_allclose(backend.features()["object_pos"][:2], obj, atol=2e-3)


def test_goal_override_puts_the_push_goal_on_the_table_half_as_far():
    env = taskforge.make(PICK_PLACE, stage="push", seed=0)
    env.reset(options={"goal_index": 2})
    backend = env.unwrapped.backend
    _, goal = backend.goal_entry("train", 2)
    f = backend.features()
    rest = f["object_pos"]
    np.testing.assert_allclose(f["goal_pos"][:2], rest[:2] + 0.5 * (goal[:2] - rest[:2]))
    assert f["goal_pos"][2] == pytest.approx(rest[2])
    np.testing.assert_allclose(backend.data.mocap_pos[0], f["goal_pos"])


# --------------------------------------------------------------------------- randomisation


def test_randomisation_changes_the_compiled_model_and_restores_it():
    env = taskforge.make(PICK_PLACE, seed=0, privileged=True)
    model = env.unwrapped.backend.model("xarm7")
    fields = ["body_mass", "geom_friction", "dof_damping", "actuator_gainprm", "actuator_biasprm", "geom_size"]
    nominal = {k: getattr(model, k).copy() for k in fields}
    gravity = model.opt.gravity.copy()
    _, info = env.reset()
    for k in fields:
        assert not np.array_equal(getattr(model, k), nominal[k]), k
    assert not np.array_equal(model.opt.gravity, gravity)
    arm, grip, cube = model.actuator("act1").id, model.actuator("gripper").id, model.geom("object_geom").id
    assert model.actuator_gainprm[arm, 0] != nominal["actuator_gainprm"][arm, 0]  # arm servo
    assert model.actuator_gainprm[grip, 0] != nominal["actuator_gainprm"][grip, 0]  # gripper servo
    assert model.geom_size[cube, 0] != nominal["geom_size"][cube, 0]  # cube size
    # The cube rests on the table at its randomised size, and MuJoCo's mid-phase box grew too.
    node = model.body_bvhadr[model.body("object").id]
    np.testing.assert_allclose(model.bvh_aabb[node, 3:], model.geom_size[cube])
    assert env.unwrapped.backend.features()["object_pos"][2] == pytest.approx(model.geom_size[cube, 2], abs=1e-3)
    # Privileged: object velocity (3) + goal (3) + one draw per randomised element.
    randomizer = env.unwrapped._randomizers["xarm7"]
    assert info["privileged"].shape == (6 + randomizer.draw_size,) == (env.unwrapped.privileged_size,)
    np.testing.assert_allclose(info["privileged"][6:], randomizer.last_draw, rtol=1e-6)
    # A second reset redraws from the nominal model; restore gives it back exactly.
    first = model.body_mass.copy()
    env.reset()
    assert not np.array_equal(model.body_mass, first)
    randomizer.restore()
    for k in fields:
        np.testing.assert_array_equal(getattr(model, k), nominal[k])
    np.testing.assert_array_equal(model.opt.gravity, gravity)


def test_same_seed_same_episode():
    def rollout():
        env = taskforge.make(PICK_PLACE, stage="pick", seed=3)
        obs, _ = env.reset()
        out = [obs]
        rng = np.random.default_rng(0)
        for _ in range(5):
            out.append(env.step(rng.uniform(-1, 1, 4))[0])
        return np.array(out)

    np.testing.assert_array_equal(rollout(), rollout())


# --------------------------------------------------------------------------- variants


def test_variants_change_the_model_as_intended():
    def backend(name):
        env = taskforge.make(XARM / name, stage="place", seed=0)
        env.unwrapped._randomizers["xarm7"].restore()  # nominal values
        return env.unwrapped.backend

    base, big, low, high = (backend(f) for f in ("pick_place.yaml", "pick_place_big_cube.yaml",
                                                 "pick_place_low_table.yaml", "pick_place_high_goals.yaml"))

    def cube(b):
        m = b.model("xarm7")
        return m.geom_size[m.geom("object_geom").id, 0], m.body_mass[m.body("object").id]

    def table_top(b):
        m = b.model("xarm7")
        g = m.geom("table").id
        return m.geom_pos[g, 2] + m.geom_size[g, 2]

    assert cube(base) == pytest.approx((0.02, 0.1)) and cube(big) == pytest.approx((0.03, 0.3))
    assert table_top(base) == pytest.approx(0.0) and table_top(low) == pytest.approx(-0.05)
    # The robot does not move with the table: same TCP at home.
    for b in (base, low):
        b.reset("xarm7", "train", 0, taskforge.backends.GoalOverride())
    np.testing.assert_allclose(base.features()["tcp_pos"], low.features()["tcp_pos"], atol=1e-6)
    assert low.features()["object_pos"][2] == pytest.approx(-0.05 + 0.02, abs=1e-3)
    goals = lambda b: np.array([b.goal_entry("train", i)[1] for i in range(b.num_goals("train"))])  # noqa: E731
    assert goals(base)[:, 2].max() <= 0.30 and goals(high)[:, 2].min() >= 0.20
    assert goals(low)[:, 2].min() >= -0.05 + 0.05 - 1e-9  # goal z is above the table top


def test_composed_scene_matches_the_reference_scene_xml():
    ref = mujoco.MjModel.from_xml_path(str(BUILTIN_ROBOT.parent / "scene.xml"))  # the documented reference scene
    env = taskforge.make(PICK_PLACE, seed=0)
    env.unwrapped._randomizers["xarm7"].restore()
    m = env.unwrapped.backend.model("xarm7")
    tcp = []
    for model in (ref, m):
        d = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, d, model.key("home").id)
        mujoco.mj_forward(model, d)
        tcp.append(d.site("link_tcp").xpos.copy())
    np.testing.assert_allclose(tcp[1], tcp[0], atol=1e-9)
    assert (m.nq, m.nv, m.nu) == (ref.nq, ref.nv, ref.nu)
    assert m.opt.timestep == ref.opt.timestep and m.opt.cone == ref.opt.cone and m.opt.impratio == ref.opt.impratio
    for name in ("object_geom", "table"):
        np.testing.assert_allclose(m.geom(name).size, ref.geom(name).size)
    assert m.body("object").mass == pytest.approx(ref.body("object").mass)
    for cam in ("front", "top", "side"):
        np.testing.assert_allclose(m.camera(cam).pos, ref.camera(cam).pos)


# --------------------------------------------------------------------------- Menagerie's model


def test_robot_model_path_is_relative_to_the_task_file_and_keeps_its_meshdir(tmp_path, monkeypatch):
    """A robot file elsewhere with meshes in its own `meshdir` (like Menagerie's `assets/`)."""
    import struct

    (tmp_path / "robot" / "assets").mkdir(parents=True)
    corners = [(0, 0, 0), (0.05, 0, 0), (0, 0.05, 0), (0, 0, 0.05)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    stl = b"\0" * 80 + struct.pack("<I", len(faces))
    for face in faces:
        stl += struct.pack("<3f", 0, 0, 0) + b"".join(struct.pack("<3f", *corners[i]) for i in face) + b"\0\0"
    (tmp_path / "robot" / "assets" / "tet.stl").write_bytes(stl)
    xml = BUILTIN_ROBOT.read_text()
    xml = xml.replace('autolimits="true"/>', 'autolimits="true" meshdir="assets"/>', 1)
    xml = xml.replace("<asset>", '<asset><mesh file="tet.stl"/>', 1)
    xml = xml.replace('<geom name="link1_geom"', '<geom name="link1_mesh" type="mesh" mesh="tet"/><geom name="link1_geom"', 1)
    (tmp_path / "robot" / "xarm7.xml").write_text(xml)
    (tmp_path / "tasks").mkdir()
    task = write_task(tmp_path / "tasks", {"robot_model": "../robot/xarm7.xml"})
    monkeypatch.chdir(XARM)  # somewhere else: paths must not depend on the working directory
    env = taskforge.make(task, seed=0)
    env.reset()
    assert env.unwrapped.backend.model("xarm7").nmesh == 1


@pytest.mark.skipif(not REFERENCE.is_file(), reason="Menagerie's xArm7 reference is not beside the repository")
def test_menagerie_model_works_with_its_pad_names(tmp_path):
    """Menagerie's xarm7.xml with its meshes stripped (the meshes are not shipped here):
    the same backend, with `pad_geoms` set to Menagerie's names, grasps and lifts the cube."""
    xml = REFERENCE.read_text()
    xml = re.sub(r"\s*<mesh file=\"[^\"]+\"/>", "", xml)
    xml = re.sub(r"<geom[^>]*mesh=\"[^\"]+\"[^>]*/>", "", xml)
    for default in ('<geom type="mesh" material="white"/>', '<geom type="mesh" contype="0" conaffinity="0" group="2"/>',
                    '<geom type="mesh" group="3"/>'):
        xml = xml.replace(default, "")
    (tmp_path / "menagerie_xarm7.xml").write_text(xml)
    pads = {"left": ["left_finger_pad_1", "left_finger_pad_2"], "right": ["right_finger_pad_1", "right_finger_pad_2"]}
    with pytest.raises(SpecError, match="pad_geoms.left"):
        taskforge.make(write_task(tmp_path, {"robot_model": "menagerie_xarm7.xml"}))
    env = taskforge.make(write_task(tmp_path, {"robot_model": "menagerie_xarm7.xml", "pad_geoms": pads}), seed=0)
    env.reset(options={"goal_index": 0})
    cube = env.unwrapped.backend.features()["object_pos"].copy()
    drive(env, cube + [0, 0, 0.10], -1.0, 25)
    drive(env, cube + [0, 0, -0.01], -1.0, 20)
    f, _ = drive(env, cube + [0, 0, -0.01], 1.0, 10)
    assert f["object_grasped"] == 1.0
    f, _ = drive(env, cube + [0, 0, 0.15], 1.0, 25)
    assert f["object_height"] >= 0.05 and f["object_grasped"] == 1.0
