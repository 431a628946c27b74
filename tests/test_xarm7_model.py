"""taskforge's own xArm7 + gripper MJCF (tasks/xarm7): loading, kinematics vs Menagerie, grasping."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import mujoco
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
ROBOT_XML = ROOT / "taskforge" / "backends" / "assets" / "xarm7" / "xarm7.xml"
SCENE_XML = ROBOT_XML.parent / "scene.xml"
# Menagerie's xArm7 description (mesh-free loader), beside the repository; optional.
REFERENCE_DIR = Path(__file__).resolve().parents[2] / "shared/reference/ufactory_xarm7"

ARM_JOINTS = [f"joint{i}" for i in range(1, 8)]
ARM_ACTUATORS = [f"act{i}" for i in range(1, 8)]
# link_tcp orientation with the gripper pointing straight down, fingers closing along world y
# (the orientation at the `home` keyframe).
R_DOWN = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])


@pytest.fixture(scope="module")
def scene() -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(str(SCENE_XML))


def arm_qpos_ids(m: mujoco.MjModel) -> np.ndarray:
    return np.array([m.jnt_qposadr[m.joint(j).id] for j in ARM_JOINTS])


def arm_act_ids(m: mujoco.MjModel) -> np.ndarray:
    return np.array([m.actuator(a).id for a in ARM_ACTUATORS])


def solve_ik(m: mujoco.MjModel, qpos: np.ndarray, pos, rot=R_DOWN, iters: int = 300) -> np.ndarray:
    """mink IK for link_tcp; returns a full qpos (only the arm joints move)."""
    import mink

    cfg = mink.Configuration(m)
    cfg.update(qpos.copy())
    task = mink.FrameTask("link_tcp", "site", position_cost=1.0, orientation_cost=0.5, lm_damping=1e-3)
    task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3.from_matrix(rot), np.asarray(pos, float)))
    posture = mink.PostureTask(m, cost=1e-3)
    posture.set_target(qpos.copy())
    limits = [mink.ConfigurationLimit(m)]
    for _ in range(iters):
        vel = mink.solve_ik(cfg, [task, posture], 0.05, "daqp", damping=1e-3, limits=limits)
        cfg.integrate_inplace(vel, 0.05)
        err = task.compute_error(cfg)
        if np.linalg.norm(err[:3]) < 1e-4 and np.linalg.norm(err[3:]) < 1e-3:
            break
    assert np.linalg.norm(err[:3]) < 1e-3, f"IK did not reach {pos}"
    return cfg.q.copy()


# --------------------------------------------------------------------------- loading


def test_scene_loads_and_steps(scene):
    m = scene
    d = mujoco.MjData(m)
    # Names a backend relies on.
    for j in ARM_JOINTS + ["left_finger_joint", "right_finger_joint", "object_joint"]:
        m.joint(j)
    for a in ARM_ACTUATORS + ["gripper"]:
        m.actuator(a)
    for g in ["left_finger_pad", "right_finger_pad", "object_geom", "table", "floor"]:
        m.geom(g)
    for s in ["link_tcp", "pinch", "goal"]:
        m.site(s)
    for c in ["front", "top"]:
        m.camera(c)
    assert m.body("goal").mocapid[0] >= 0
    assert m.key("home").id == 0
    assert m.opt.timestep == pytest.approx(0.002)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST

    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    mujoco.mj_forward(m, d)
    assert d.ncon == 0, "robot touches something at home (self-collision or table)"
    for _ in range(500):
        mujoco.mj_step(m, d)
    assert np.all(np.isfinite(d.qpos))
    assert not any(d.warning[i].number for i in range(len(d.warning)))
    # The cube rests on the table top (z = 0) where the scene puts it.
    obj = d.body("object").xpos
    assert obj[2] == pytest.approx(0.02, abs=1e-3)
    assert np.allclose(obj[:2], [0.45, 0.0], atol=1e-3)


def test_robot_file_loads_alone_and_names_survive_attach(scene):
    robot = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
    assert robot.nq == 9 and robot.nu == 8
    for i in range(robot.njnt):
        assert scene.joint(robot.joint(i).name).type == robot.jnt_type[i]
    for i in range(robot.nu):
        np.testing.assert_allclose(scene.actuator(robot.actuator(i).name).gainprm, robot.actuator_gainprm[i])


def test_gripper_control_convention(scene):
    """ctrl 0 = open (88 mm between the pads), 255 = closed; fingers move symmetrically."""
    m = scene
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    g = m.actuator("gripper").id
    assert tuple(m.actuator_ctrlrange[g]) == (0.0, 255.0)
    left, right = m.geom("left_finger_pad"), m.geom("right_finger_pad")

    def gap() -> float:
        return float(np.linalg.norm(d.geom_xpos[left.id] - d.geom_xpos[right.id]) - left.size[1] - right.size[1])

    for ctrl, expected in [(255, 0.0), (127.5, 0.044), (0, 0.088)]:
        d.ctrl[g] = ctrl
        for _ in range(400):
            mujoco.mj_step(m, d)
        assert gap() == pytest.approx(expected, abs=1.5e-3)
        assert d.joint("left_finger_joint").qpos[0] == pytest.approx(d.joint("right_finger_joint").qpos[0], abs=1e-4)
    for name in ["left_finger_pad", "right_finger_pad"]:
        assert m.geom(name).condim[0] >= 4 and m.geom(name).friction[0] >= 1.0


# --------------------------------------------------------------------------- kinematics


def _load_reference() -> mujoco.MjModel:
    if not (REFERENCE_DIR / "reference_nomesh.py").exists():
        pytest.skip(f"Menagerie reference not available at {REFERENCE_DIR}")
    spec = importlib.util.spec_from_file_location("_xarm7_reference_nomesh", REFERENCE_DIR / "reference_nomesh.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.load()


def test_tcp_matches_menagerie_reference():
    ref = _load_reference()
    ours = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
    d_ref, d_ours = mujoco.MjData(ref), mujoco.MjData(ours)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(50):
        for name in ARM_JOINTS:
            lo, hi = ours.joint(name).range
            assert np.allclose([lo, hi], ref.joint(name).range)
            q = rng.uniform(lo, hi)
            d_ours.qpos[ours.jnt_qposadr[ours.joint(name).id]] = q
            d_ref.qpos[ref.jnt_qposadr[ref.joint(name).id]] = q
        mujoco.mj_kinematics(ours, d_ours)
        mujoco.mj_kinematics(ref, d_ref)
        worst = max(worst, np.linalg.norm(d_ours.site("link_tcp").xpos - d_ref.site("link_tcp").xpos))
        np.testing.assert_allclose(d_ours.site("link_tcp").xmat, d_ref.site("link_tcp").xmat, atol=1e-3)
    assert worst < 2e-3, f"TCP differs from Menagerie's by {worst * 1000:.2f} mm"


def test_arm_dynamics_parameters_match_reference():
    ref = _load_reference()
    ours = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
    for i in range(1, 8):
        a, b = ours.actuator(f"act{i}"), ref.actuator(f"act{i}")
        np.testing.assert_allclose(a.gainprm[:3], b.gainprm[:3])
        np.testing.assert_allclose(a.biasprm[:3], b.biasprm[:3])
        np.testing.assert_allclose(a.forcerange, b.forcerange)
        np.testing.assert_allclose(a.ctrlrange, ours.joint(f"joint{i}").range)
        body = f"link{i}"
        assert ours.body(body).mass[0] == pytest.approx(ref.body(body).mass[0])
    # Same total mass (the finger bodies carry the removed knuckle linkage).
    assert ours.body_mass.sum() == pytest.approx(ref.body_mass.sum(), abs=1e-3)


# --------------------------------------------------------------------------- control


def test_home_pose_is_held_by_position_actuators(scene):
    m = scene
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    mujoco.mj_forward(m, d)
    qa = arm_qpos_ids(m)
    q0, tcp0 = d.qpos[qa].copy(), d.site("link_tcp").xpos.copy()
    for _ in range(int(1.0 / m.opt.timestep)):
        mujoco.mj_step(m, d)
    assert np.abs(d.qpos[qa] - q0).max() < 5e-3
    assert np.linalg.norm(d.site("link_tcp").xpos - tcp0) < 2e-3


@pytest.mark.parametrize(
    "cube_xy, tcp_height",
    [((0.45, 0.0), 0.01), ((0.35, 0.15), 0.005), ((0.55, -0.15), 0.02), ((0.30, -0.25), 0.01)],
)
def test_gripper_holds_cube_while_lifting(scene, cube_xy, tcp_height):
    m = scene
    d = mujoco.MjData(m)
    qa, acts, grip = arm_qpos_ids(m), arm_act_ids(m), m.actuator("gripper").id
    obj = m.jnt_qposadr[m.joint("object_joint").id]
    half = m.geom("object_geom").size[0]
    mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
    d.qpos[obj : obj + 7] = [*cube_xy, half, 1, 0, 0, 0]

    # Open gripper around the cube, link_tcp a little below the cube centre.
    q = solve_ik(m, d.qpos, [*cube_xy, tcp_height])
    d.qpos[qa] = q[qa]
    d.ctrl[acts] = q[qa]
    d.ctrl[grip] = 0
    mujoco.mj_forward(m, d)
    for _ in range(100):
        mujoco.mj_step(m, d)

    d.ctrl[grip] = 255  # close
    for _ in range(300):
        mujoco.mj_step(m, d)
    tcp0 = d.site("link_tcp").xpos.copy()
    cube0 = d.qpos[obj : obj + 3].copy()
    assert d.joint("left_finger_joint").qpos[0] < 0.044 - 0.015, "fingers closed on nothing"

    # Lift 10 cm with the arm's position actuators (smooth 1 s ramp, then 0.5 s hold).
    q_up = solve_ik(m, d.qpos, tcp0 + [0, 0, 0.10])[qa]
    q_start = d.qpos[qa].copy()
    ramp = 500
    for k in range(ramp + 250):
        a = min(1.0, k / ramp)
        d.ctrl[acts] = q_start + (q_up - q_start) * (3 * a * a - 2 * a**3)
        mujoco.mj_step(m, d)

    tcp1, cube1 = d.site("link_tcp").xpos, d.qpos[obj : obj + 3]
    assert tcp1[2] - tcp0[2] >= 0.08
    assert cube1[2] - cube0[2] >= 0.08, "cube did not rise with the gripper"
    slip = np.linalg.norm((cube1 - tcp1) - (cube0 - tcp0))
    assert slip < 5e-3, f"cube slipped {slip * 1000:.1f} mm in the gripper"
