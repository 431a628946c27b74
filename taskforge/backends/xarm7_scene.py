"""The xArm7 backend's world: the scene composed around a robot MJCF with `mujoco.MjSpec`, the
IK-only robot model, and the train/test goal sets.

The scene is built here rather than read from `taskforge/backends/assets/xarm7/scene.xml` so that a task variant
changes the table height, the cube and the regions with YAML only, and so that any robot file
with the names below (taskforge's `taskforge/backends/assets/xarm7/xarm7.xml` or MuJoCo Menagerie's
`ufactory_xarm7/xarm7.xml`) can be dropped in. With the defaults the compiled scene equals
`scene.xml` in everything the backend uses (physics options, table top at z = 0, robot base at
z = 0.12 on a pedestal, 4 cm 0.1 kg cube, goal mocap, cameras `front`/`top`/`side`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from taskforge.backends.base import draw_starts_apart
from taskforge.spec.backends import XArm7BackendSpec

# The repository's tasks/ folder, beside the taskforge package (a source checkout or an editable
# install; tasks/ is not part of the built package).
BUILTIN_ROBOT = Path(__file__).resolve().parent / "assets" / "xarm7" / "xarm7.xml"  # package data

ARM_JOINTS = tuple(f"joint{i}" for i in range(1, 8))
ARM_ACTUATORS = tuple(f"act{i}" for i in range(1, 8))
GRIPPER_ACTUATOR = "gripper"
TCP_SITE = "link_tcp"
HOME_KEY = "home"
OBJECT_BODY, OBJECT_GEOM, OBJECT_JOINT = "object", "object_geom", "object_joint"
GOAL_BODY = "goal"
# The table spans x in [-0.45, 1.05], y in [-0.7, 0.7] (as in scene.xml); the room floor is 0.75 m
# below the default table top.
_TABLE_X, _TABLE_Y, _FLOOR_Z = (-0.45, 1.05), (-0.7, 0.7), -0.75
_CAMERAS = (  # name, position, xyaxes: those of scene.xml, looking at the workspace around x = 0.45
    ("front", [1.35, 0, 0.55], [0, 1, 0, -0.447, 0, 0.894]),
    ("top", [0.45, 0, 1.4], [0, -1, 0, 1, 0, 0]),
    ("side", [0.45, -1.1, 0.45], [1, 0, 0, 0, 0.303, 0.953]),
)


def robot_path(spec: XArm7BackendSpec, task_file: str | Path) -> Path:
    """The robot MJCF: the built-in model, or `robot_model` relative to the task file."""
    if spec.robot_model is None:
        return BUILTIN_ROBOT
    ref = Path(spec.robot_model).expanduser()
    return ref if ref.is_absolute() else Path(task_file).resolve().parent / ref


def required_names(spec: XArm7BackendSpec) -> list[tuple[str, mujoco.mjtObj, str]]:
    """(field path, kind, name) of every element the backend looks up in the robot model."""
    out = [("robot_model", mujoco.mjtObj.mjOBJ_JOINT, j) for j in ARM_JOINTS]
    out += [("robot_model", mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in (*ARM_ACTUATORS, GRIPPER_ACTUATOR)]
    out.append(("robot_model", mujoco.mjtObj.mjOBJ_SITE, TCP_SITE))
    for side in ("left", "right"):
        for i, g in enumerate(getattr(spec.pad_geoms, side)):
            out.append((f"pad_geoms.{side}[{i}]", mujoco.mjtObj.mjOBJ_GEOM, g))
    return out


def load_robot(path: Path) -> mujoco.MjSpec:
    return mujoco.MjSpec.from_file(str(path))


def build_scene(spec: XArm7BackendSpec, robot: mujoco.MjSpec) -> mujoco.MjModel:
    """Compile table + pedestal + robot + cube + goal marker + lights + cameras."""
    s = mujoco.MjSpec()
    s.modelname = "taskforge_xarm7"
    s.compiler.degree = False
    s.compiler.autolimits = True
    opt = s.option
    # scene.xml's physics: implicit damping, elliptic cones with a high impratio against slip.
    opt.timestep = spec.control.physics_timestep
    opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    opt.impratio = 10.0
    opt.iterations = 50
    opt.ls_iterations = 20
    s.stat.center = [0.35, 0.0, 0.2]
    s.stat.extent = 0.9
    s.visual.global_.offwidth = 640
    s.visual.global_.offheight = 480
    s.visual.global_.azimuth = 150
    s.visual.global_.elevation = -25
    s.visual.headlight.diffuse = [0.6, 0.6, 0.6]
    s.visual.headlight.ambient = [0.3, 0.3, 0.3]
    s.visual.headlight.specular = [0.0, 0.0, 0.0]

    s.add_texture(name="groundplane", type=mujoco.mjtTexture.mjTEXTURE_2D, builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
                  mark=mujoco.mjtMark.mjMARK_EDGE, rgb1=[0.2, 0.3, 0.4], rgb2=[0.1, 0.2, 0.3],
                  markrgb=[0.8, 0.8, 0.8], width=300, height=300)
    ground = s.add_material(name="groundplane", texuniform=True, texrepeat=[5, 5], reflectance=0.2)
    ground.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "groundplane"
    s.add_material(name="table", rgba=[0.55, 0.42, 0.3, 1])
    s.add_material(name="pedestal", rgba=[0.25, 0.25, 0.25, 1])
    s.add_material(name="object", rgba=[0.85, 0.2, 0.2, 1])
    s.add_material(name="goal", rgba=[0.1, 0.85, 0.2, 0.45])

    w = s.worldbody
    w.add_light(pos=[0.3, 0, 1.8], dir=[0, 0, -1], directional=True, diffuse=[0.5, 0.5, 0.5])
    w.add_light(pos=[1.0, -0.8, 1.4], dir=[-0.5, 0.5, -0.7], diffuse=[0.35, 0.35, 0.35], castshadow=False)
    box, top = mujoco.mjtGeom.mjGEOM_BOX, spec.table_height
    w.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, pos=[0, 0, _FLOOR_Z], size=[0, 0, 0.05],
               material="groundplane")
    half = [(_TABLE_X[1] - _TABLE_X[0]) / 2, (_TABLE_Y[1] - _TABLE_Y[0]) / 2, (top - _FLOOR_Z) / 2]
    w.add_geom(name="table", type=box, size=half, material="table",
               pos=[(_TABLE_X[0] + _TABLE_X[1]) / 2, (_TABLE_Y[0] + _TABLE_Y[1]) / 2, (top + _FLOOR_Z) / 2])

    base = robot.worldbody.first_body()
    if base is None:
        raise ValueError("the robot file has no body under <worldbody>")
    base_z = float(base.pos[2])
    if base_z > top + 1e-6:  # pedestal from the table top up to the robot base
        w.add_geom(name="pedestal", type=mujoco.mjtGeom.mjGEOM_CYLINDER, material="pedestal",
                   pos=[float(base.pos[0]), float(base.pos[1]), (top + base_z) / 2], size=[0.08, (base_z - top) / 2, 0])
    if spec.gravity_compensation:
        _set_gravcomp(base)
    frame = w.add_frame()
    frame.attach_body(base, "", "")

    size = spec.cube.size
    x0, y0 = (sum(spec.object_region.x) / 2, sum(spec.object_region.y) / 2)
    obj = w.add_body(name=OBJECT_BODY, pos=[x0, y0, top + size])
    obj.add_freejoint(name=OBJECT_JOINT)
    obj.add_geom(name=OBJECT_GEOM, type=box, size=[size] * 3, mass=spec.cube.mass, material="object",
                 condim=4, friction=[spec.cube.friction, 0.01, 0.0001])
    goal = w.add_body(name=GOAL_BODY, mocap=True, pos=[x0, y0, top + 0.15])
    goal.add_site(name=GOAL_BODY, type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.02, 0, 0], material="goal", group=0)

    for name, pos, xyaxes in _CAMERAS:
        camera = w.add_camera(name=name, pos=pos, fovy=45)
        camera.alt.type = mujoco.mjtOrientation.mjORIENTATION_XYAXES
        camera.alt.xyaxes = xyaxes
    return s.compile()


def _set_gravcomp(body: mujoco.MjsBody) -> None:
    for child in body.bodies:
        child.gravcomp = 1.0
        _set_gravcomp(child)


def build_ik_model(robot: mujoco.MjSpec) -> mujoco.MjModel:
    """The robot's kinematic chain only: the 7 arm joints (every other joint welded at its
    reference position), no geoms, tendons, equalities, actuators or keyframes. IK on it costs a
    7-dof QP and a kinematics pass over a dozen bodies, whatever the gripper or scene."""
    ik = robot.copy()
    for joint in list(ik.joints):
        if joint.name not in ARM_JOINTS:
            joint.delete()
    for elements in (ik.tendons, ik.equalities, ik.actuators, ik.keys, ik.sensors, ik.excludes, ik.pairs, ik.geoms):
        for element in list(elements):
            element.delete()
    ik.compiler.boundmass = 1e-6  # bodies whose mass came from (deleted) geoms
    ik.compiler.boundinertia = 1e-9
    return ik.compile()


def home_qpos(robot_model: mujoco.MjModel) -> np.ndarray:
    """The 7 arm joint angles of the robot's `home` keyframe (qpos0 if it has none), clipped
    into the joint ranges."""
    key = mujoco.mj_name2id(robot_model, mujoco.mjtObj.mjOBJ_KEY, HOME_KEY)
    qpos = robot_model.key_qpos[key] if key >= 0 else robot_model.qpos0
    out = np.empty(len(ARM_JOINTS))
    for i, name in enumerate(ARM_JOINTS):
        j = robot_model.joint(name).id
        lo, hi = robot_model.jnt_range[j] if robot_model.jnt_limited[j] else (-np.inf, np.inf)
        out[i] = np.clip(qpos[robot_model.jnt_qposadr[j]], lo, hi)
    return out


# --- goal sets --------------------------------------------------------------------------------


@dataclass(frozen=True)
class GoalSet:
    """One split: `objects[i]` (x, y) is the cube's start and `goals[i]` (x, y, z above the
    table top) the goal of entry i."""

    objects: np.ndarray
    goals: np.ndarray


class GoalRegionTooSmall(ValueError):
    pass


_CHUNK = 1024  # candidates per draw: fixed, so entry i never depends on the split's count


def make_goal_sets(spec: XArm7BackendSpec, seed: int, n_train: int, n_test: int) -> tuple[GoalSet, GoalSet]:
    """Train and test entries drawn from `goals.seed`.

    Goals: the checkerboard split of `XArm7GoalSplitSpec` (train in even cells, test in odd
    cells, each at least `margin` inside its cell), so the splits are disjoint with a gap of at
    least 2 x margin. Cube starts: uniform over `object_region`, redrawn until at least
    `min_goal_distance` from the entry's goal horizontally. Each split has its own child
    generator and draws in fixed-size chunks, so entry i of a split depends only on the seed
    and the regions: never on either split's count (a larger count appends entries).
    """
    train_rng, test_rng = np.random.default_rng(seed).spawn(2)
    return _split(spec, train_rng, 0, n_train), _split(spec, test_rng, 1, n_test)


def fresh_train_entry(spec: XArm7BackendSpec, rng: np.random.Generator) -> GoalSet:
    """One train entry drawn afresh from `rng` (`goals.train.draw: fresh`): a goal in the train
    cells and its cube start, by the same rule as the train split's entries, so fresh goals
    keep the checkerboard's gap to the held-out ones."""
    return _split(spec, rng, 0, 1)


def _split(spec: XArm7BackendSpec, rng: np.random.Generator, parity: int, count: int) -> GoalSet:
    region, split = spec.goal_region, spec.goal_split
    low = np.array([region.x[0], region.y[0], region.z[0]])
    high = np.array([region.x[1], region.y[1], region.z[1]])
    margin = split.margin / split.cell
    goals, objects, total, chunks = [], [], 0, 0
    while total < count:
        cand = rng.uniform(low, high, size=(_CHUNK, 3))
        # Cells are anchored at the world origin (z: the table top), so a point's colour does
        # not depend on the region's bounds. The margin applies along the axes the region
        # extends in (a flat z, e.g. goals on the table, has one value and one cell).
        cell = cand / split.cell
        index = np.floor(cell)
        frac = cell - index
        inside = np.all(((frac >= margin) & (frac <= 1 - margin)) | (high == low), axis=1)
        chosen = cand[inside & (index.sum(axis=1).astype(np.int64) % 2 == parity)]
        chunks += 1
        if total == 0 and len(chosen) == 0 and chunks >= 64:
            raise GoalRegionTooSmall(
                f"could not draw {'train' if parity == 0 else 'test'} goals: the goal region has (almost) no "
                f"checkerboard cell of that colour; enlarge goal_region or reduce goal_split.cell ({split.cell:g}) / margin"
            )
        goals.append(chosen)
        objects.append(place_cubes(spec, chosen, rng))
        total += len(chosen)
    return GoalSet(np.concatenate(objects)[:count], np.concatenate(goals)[:count])


def place_cubes(spec: XArm7BackendSpec, goals: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Cube starts (x, y) for goals (n x >=2): uniform over `object_region`, redrawn until at
    least `min_goal_distance` from their goal horizontally. Used for the goal sets and for
    `randomization.object_start: random`."""
    obj_low = np.array([spec.object_region.x[0], spec.object_region.y[0]])
    obj_high = np.array([spec.object_region.x[1], spec.object_region.y[1]])
    starts = draw_starts_apart(obj_low, obj_high, goals, spec.min_goal_distance, rng)
    if starts is not None:
        return starts
    raise GoalRegionTooSmall(
        f"could not place the cube at least min_goal_distance ({spec.min_goal_distance:g} m) from some goals; "
        "reduce min_goal_distance or enlarge object_region/goal_region"
    )
