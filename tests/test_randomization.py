"""Physics randomisation on a real Meta-World model: reproducible per seed, changes the model,
restores the nominal values; noise and latency behave as specified."""

from __future__ import annotations

import numpy as np
import pytest

from taskforge import load_task
from taskforge.backends import make_backend
from taskforge.randomization import ActionLatency, AdditiveNoise, PhysicsRandomizer, sample
from taskforge.spec import Distribution, LatencySpec, NoiseSpec
from tests.conftest import PICK_PLACE

ARRAYS = ["body_mass", "body_inertia", "geom_friction", "dof_damping", "actuator_gainprm", "actuator_biasprm", "geom_size", "geom_rbound"]


@pytest.fixture(scope="module")
def task():
    return load_task(PICK_PLACE)


@pytest.fixture()
def model(task):
    backend = make_backend(task, PICK_PLACE)
    return backend.model(backend.task_names[0]), backend.object_geoms(backend.task_names[0])


def snapshot(model) -> dict[str, np.ndarray]:
    state = {name: getattr(model, name).copy() for name in ARRAYS}
    state["gravity"] = model.opt.gravity.copy()
    return state


def test_same_seed_same_draws_and_model(task, model):
    m, obj = model
    rnd = PhysicsRandomizer(m, task.randomization.physics, obj)
    a = rnd.apply(np.random.default_rng(7))
    after_a = snapshot(m)
    rnd.apply(np.random.default_rng(8))
    b = rnd.apply(np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    for name, value in snapshot(m).items():
        np.testing.assert_array_equal(value, after_a[name], err_msg=name)


def test_draw_changes_every_target_and_restore_gives_nominal(task, model):
    m, obj = model
    nominal = snapshot(m)
    rnd = PhysicsRandomizer(m, task.randomization.physics, obj)
    rnd.apply(np.random.default_rng(0))
    changed = snapshot(m)
    for name in ("body_mass", "body_inertia", "geom_friction", "actuator_gainprm", "actuator_biasprm", "geom_size", "gravity"):
        assert not np.array_equal(changed[name], nominal[name]), name
    assert not np.array_equal(changed["dof_damping"], nominal["dof_damping"])
    # Ratios stay inside the table's ranges.
    moved = nominal["body_mass"] > 0
    ratio = changed["body_mass"][moved] / nominal["body_mass"][moved]
    assert ratio.min() >= 0.5 - 1e-9 and ratio.max() <= 1.5 + 1e-9
    # The position servo keeps bias = -gain (its set point does not move).
    np.testing.assert_allclose(m.actuator_biasprm[:, 1], -m.actuator_gainprm[:, 0])
    rnd.restore()
    for name, value in snapshot(m).items():
        np.testing.assert_array_equal(value, nominal[name], err_msg=name)


def test_no_drift_over_many_draws(task, model):
    m, obj = model
    nominal = snapshot(m)
    rnd = PhysicsRandomizer(m, task.randomization.physics, obj)
    rng = np.random.default_rng(1)
    for _ in range(200):
        rnd.apply(rng)
    rnd.restore()
    for name, value in snapshot(m).items():
        np.testing.assert_array_equal(value, nominal[name], err_msg=name)


def test_object_size_scales_only_the_object_geom_with_one_shared_draw(task, model):
    m, obj = model
    size_term = [t for t in task.randomization.physics if t.target == "object_size"]
    nominal = m.geom_size.copy()
    PhysicsRandomizer(m, size_term, obj).apply(np.random.default_rng(3))
    changed = np.flatnonzero((m.geom_size != nominal).any(axis=1))
    assert [m.geom(i).name for i in changed] == obj
    ratio = m.geom_size[changed[0]][:2] / nominal[changed[0]][:2]
    assert ratio[0] == pytest.approx(ratio[1]) and 0.9 <= ratio[0] <= 1.1


@pytest.mark.parametrize(
    "dist,check",
    [
        (Distribution(dist="uniform", low=0.7, high=1.3), lambda x: 0.7 <= x.min() and x.max() <= 1.3 and abs(x.mean() - 1.0) < 0.01),
        (Distribution(dist="loguniform", low=0.3, high=3.0), lambda x: abs(np.log(x).mean() - np.log(0.3 * 3.0) / 2) < 0.02 and 0.3 <= x.min() and x.max() <= 3.0),
        (Distribution(dist="normal", mean=0.0, std=0.4), lambda x: abs(x.std() - 0.4) < 0.01),
    ],
)
def test_distributions(dist, check):
    assert check(sample(dist, np.random.default_rng(0), 20000))


def test_additive_noise_per_episode_is_constant_within_an_episode():
    noise = AdditiveNoise(NoiseSpec(per_episode=Distribution(dist="normal", std=1.0)), 3)
    rng = np.random.default_rng(0)
    noise.reset(rng)
    first, second = noise(np.zeros(3), rng), noise(np.zeros(3), rng)
    np.testing.assert_array_equal(first, second)
    noise.reset(rng)
    assert not np.array_equal(noise(np.zeros(3), rng), first)


def test_latency_delays_actions_by_the_drawn_number_of_steps():
    latency = ActionLatency(LatencySpec(min_steps=2, max_steps=2), 1)
    latency.reset(np.random.default_rng(0))
    out = [latency(np.array([float(i)]))[0] for i in range(1, 6)]
    assert out == [0.0, 0.0, 1.0, 2.0, 3.0]


def test_backlash_holds_within_the_play_and_drags_beyond_it():
    from taskforge.randomization import ActionBacklash

    backlash = ActionBacklash(Distribution(dist="uniform", low=0.4, high=0.4), 1)
    backlash.reset(np.random.default_rng(0))
    inputs = [0.1, 0.3, 0.5, 0.4, 0.2, 0.0, -0.5]
    out = [round(float(backlash(np.array([x]))[0]), 6) for x in inputs]
    # play of ±0.2: nothing until the input is 0.2 away, then the output trails by 0.2
    assert out == [0.0, 0.1, 0.3, 0.3, 0.3, 0.2, -0.3]


def test_backlash_width_is_drawn_per_episode_and_off_by_default():
    from taskforge.randomization import ActionBacklash

    off = ActionBacklash(None, 2)
    off.reset(np.random.default_rng(0))
    np.testing.assert_array_equal(off(np.array([0.01, -0.01])), [0.01, -0.01])
    on = ActionBacklash(Distribution(dist="uniform", low=0.0, high=0.2), 4)
    on.reset(np.random.default_rng(1))
    first = on.half.copy()
    on.reset(np.random.default_rng(2))
    assert not np.array_equal(first, on.half) and (on.half <= 0.1).all()


def test_joint_range_shifts_the_limits_of_limited_hinges_only():
    """Learning Dexterity's joint-limit row (additive N(0, 0.15) rad) on the xArm7: every arm
    joint's range moves by its own draw, both limits together; the finger slides keep theirs."""
    import mujoco

    from taskforge.spec import PhysicsTermSpec
    from tests.conftest import ROOT

    xarm = ROOT / "tasks/xarm7/pick_place.yaml"
    xtask = load_task(xarm)
    m = make_backend(xtask, xarm).model("xarm7")
    nominal = m.jnt_range.copy()
    term = PhysicsTermSpec(target="joint_range", op="add", dist="normal", mean=0.0, std=0.15)
    rnd = PhysicsRandomizer(m, [term])
    draw = rnd.apply(np.random.default_rng(0))
    hinges = [j for j in range(m.njnt) if m.jnt_limited[j] and m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    assert len(hinges) >= 7 and draw.size == len(hinges) and np.all(draw != 0.0)
    np.testing.assert_allclose(m.jnt_range[hinges] - nominal[hinges], np.stack([draw, draw], axis=1))
    others = [j for j in range(m.njnt) if j not in hinges]
    np.testing.assert_array_equal(m.jnt_range[others], nominal[others])
    rnd.restore()
    np.testing.assert_array_equal(m.jnt_range, nominal)


def test_an_unknown_physics_target_lists_the_registered_ones(model):
    from taskforge.randomization import PHYSICS_TARGETS
    from taskforge.spec import PhysicsTermSpec, SpecError

    m, obj = model
    with pytest.raises(SpecError) as exc:
        PhysicsRandomizer(m, [PhysicsTermSpec(target="body_masss", dist="uniform", low=0.5, high=1.5)], obj, "task.yaml")
    message = str(exc.value)
    assert message.startswith("task.yaml: randomization.physics[0].target: unknown physics target 'body_masss'")
    assert "did you mean 'body_mass'" in message and "joint_range" in message and set(PHYSICS_TARGETS) >= {"joint_range", "gravity"}
