"""Physics randomisation of a compiled MuJoCo model, in the style of the *Learning Dexterity*
table (OpenAI et al., 2019): masses, friction, joint damping, joint limits, actuator gains,
gravity and object size, each scaled or offset by a draw at every reset.

Each target is one decorated function (`@physics_target`) in this file: its record names the
model arrays it changes and the elements its `names` match. A new target is one such function.

Why snapshot-and-restore: every draw starts from the nominal model, so values never drift
episode after episode, and `restore()` gives the exact nominal model back.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from taskforge.randomization.distributions import sample
from taskforge.spec import PhysicsTermSpec, SpecError, SpecIssue, expected_one_of

ApplyFn = Callable[[mujoco.MjModel, np.ndarray, np.ndarray, str], None]
"""`apply(model, index, value, op)`: write one draw per indexed element into the model."""


@dataclass(frozen=True)
class PhysicsTarget:
    """One randomisable kind of model parameter: what it writes, which elements it can name, and
    the model arrays to snapshot (restored before every draw)."""

    name: str
    apply: ApplyFn
    arrays: tuple[str, ...]
    element: mujoco.mjtObj | None
    """The kind of named element `names` matches; None for a target without names (gravity)."""
    ops: tuple[str, ...] = ("scale", "add")
    select: Callable[[mujoco.MjModel, list[int]], list[int]] | None = None
    """Narrows the matched elements (e.g. drops massless bodies) or maps them to array rows."""
    object_default: bool = False
    """Empty `names` means the backend's object geoms, not every element."""


PHYSICS_TARGETS: dict[str, PhysicsTarget] = {}
"""Every `randomization.physics[].target`, by name. Add one with `@physics_target`."""

_COUNT = {
    mujoco.mjtObj.mjOBJ_BODY: lambda m: m.nbody,
    mujoco.mjtObj.mjOBJ_GEOM: lambda m: m.ngeom,
    mujoco.mjtObj.mjOBJ_JOINT: lambda m: m.njnt,
    mujoco.mjtObj.mjOBJ_ACTUATOR: lambda m: m.nu,
}


def physics_target(
    name: str,
    arrays: tuple[str, ...],
    element: mujoco.mjtObj | None,
    ops: tuple[str, ...] = ("scale", "add"),
    select: Callable[[mujoco.MjModel, list[int]], list[int]] | None = None,
    object_default: bool = False,
) -> Callable[[ApplyFn], ApplyFn]:
    """Register the decorated `apply` function as the physics target `name` (Isaac Lab's event
    terms are the model): one function and its record is all a new target needs."""
    def register(apply: ApplyFn) -> ApplyFn:
        PHYSICS_TARGETS[name] = PhysicsTarget(name, apply, arrays, element, ops, select, object_default)
        return apply

    return register


_RESIZABLE_GEOMS = {
    mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_ELLIPSOID,
    mujoco.mjtGeom.mjGEOM_CYLINDER, mujoco.mjtGeom.mjGEOM_BOX,
}


@dataclass(frozen=True)
class _BoundTerm:
    spec: PhysicsTermSpec
    index: np.ndarray
    """Indices into the target's model array (bodies, geoms, dofs, actuators or gravity axes)."""


class PhysicsRandomizer:
    """Applies a task's `randomization.physics` terms to one `MjModel`, in place."""

    def __init__(
        self,
        model: mujoco.MjModel,
        terms: Sequence[PhysicsTermSpec],
        object_geoms: Sequence[str] = (),
        file: str | Path = "<task>",
    ):
        self.model = model
        issues: list[SpecIssue] = []
        self._terms = []
        for i, term in enumerate(terms):
            path = f"randomization.physics[{i}]"
            try:
                self._terms.append(_BoundTerm(term, _resolve(model, term, object_geoms, file, path)))
            except SpecError as exc:
                issues += exc.issues
        if issues:
            raise SpecError(issues)
        self._nominal = {
            name: np.copy(_array(model, name))
            for term in self._terms
            for name in PHYSICS_TARGETS[term.spec.target].arrays
        }
        self.last_draw = np.zeros(self.draw_size)

    @property
    def draw_size(self) -> int:
        """Length of `last_draw`: one number per randomised element (privileged observation)."""
        return int(sum(t.index.size for t in self._terms))

    def restore(self) -> None:
        for name, nominal in self._nominal.items():
            _array(self.model, name)[...] = nominal

    def apply(self, rng: np.random.Generator) -> np.ndarray:
        """Restore the nominal model, draw every term and write it into the model.

        Returns the draws (scale factors or offsets), one per element, for the critic.
        """
        self.restore()
        draws = []
        for term in self._terms:
            spec, index = term.spec, term.index
            size = index.size if spec.per_element else 1
            value = np.broadcast_to(sample(spec, rng, size), index.shape)
            PHYSICS_TARGETS[spec.target].apply(self.model, index, value, spec.op)
            draws.append(value)
        self.last_draw = np.concatenate(draws) if draws else np.zeros(0)
        return self.last_draw


def _array(model: mujoco.MjModel, name: str) -> np.ndarray:
    return model.opt.gravity if name == "opt.gravity" else getattr(model, name)


def _combine(nominal: np.ndarray, value: np.ndarray, op: str) -> np.ndarray:
    return nominal * value if op == "scale" else nominal + value


def _massive_bodies(model: mujoco.MjModel, bodies: list[int]) -> list[int]:
    return [i for i in bodies if i > 0 and model.body_mass[i] > 0]  # the world has no mass


@physics_target("body_mass", ("body_mass", "body_inertia"), mujoco.mjtObj.mjOBJ_BODY, select=_massive_bodies)
def _apply_body_mass(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    old = model.body_mass[idx].copy()
    # A body must keep a positive mass; a draw may not take it below a thousandth of nominal.
    new = np.maximum(_combine(old, value, op), old * 1e-3)
    model.body_mass[idx] = new
    # Inertia scales with mass for a fixed shape; keeps the model physically consistent.
    model.body_inertia[idx] *= (new / np.where(old > 0, old, 1.0))[:, None]


@physics_target("geom_friction", ("geom_friction",), mujoco.mjtObj.mjOBJ_GEOM)
def _apply_friction(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    model.geom_friction[idx] = np.maximum(_combine(model.geom_friction[idx], value[:, None], op), 0.0)


def _joint_dofs(model: mujoco.MjModel, joints: list[int]) -> list[int]:
    """Joint ids -> the dof ids they own (a free joint has 6, a ball 3, hinge/slide 1)."""
    width = {mujoco.mjtJoint.mjJNT_FREE: 6, mujoco.mjtJoint.mjJNT_BALL: 3}
    return [model.jnt_dofadr[j] + k for j in joints for k in range(width.get(model.jnt_type[j], 1))]


@physics_target("dof_damping", ("dof_damping",), mujoco.mjtObj.mjOBJ_JOINT, select=_joint_dofs)
def _apply_damping(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    model.dof_damping[idx] = np.maximum(_combine(model.dof_damping[idx], value, op), 0.0)


def _limited_hinges(model: mujoco.MjModel, joints: list[int]) -> list[int]:
    """Hinge joints with limits: the table's draws are angles (rad). Slide joints (a gripper's
    fingers) are left alone, where a shift in radians would be one in metres."""
    return [j for j in joints if model.jnt_limited[j] and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]


@physics_target("joint_range", ("jnt_range",), mujoco.mjtObj.mjOBJ_JOINT, select=_limited_hinges)
def _apply_joint_range(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    """Learning Dexterity's joint limits (additive N(0, 0.15) rad): `add` shifts both limits of a
    joint by its draw (a calibration offset); `scale` widens or narrows the range about its centre."""
    low, high = model.jnt_range[idx, 0].copy(), model.jnt_range[idx, 1].copy()
    if op == "add":
        model.jnt_range[idx, 0], model.jnt_range[idx, 1] = low + value, high + value
    else:
        centre, half = (low + high) / 2, (high - low) / 2 * np.maximum(value, 0.0)
        model.jnt_range[idx, 0], model.jnt_range[idx, 1] = centre - half, centre + half


@physics_target("actuator_gain", ("actuator_gainprm", "actuator_biasprm"), mujoco.mjtObj.mjOBJ_ACTUATOR)
def _apply_actuator_gain(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    old = model.actuator_gainprm[idx, 0].copy()
    new = _combine(old, value, op)
    model.actuator_gainprm[idx, 0] = new
    # A position servo's bias is (0, -kp, -kv): scale it with kp or the servo's set point moves.
    ratio = new / np.where(old != 0, old, 1.0)
    model.actuator_biasprm[idx, 1:3] *= ratio[:, None]


@physics_target("gravity", ("opt.gravity",), None)
def _apply_gravity(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    model.opt.gravity[idx] = _combine(model.opt.gravity[idx], value, op)


def _resizable(model: mujoco.MjModel, geoms: list[int]) -> list[int]:
    bad = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom {g}" for g in geoms if model.geom_type[g] not in _RESIZABLE_GEOMS]
    if bad:
        raise ValueError(f"object_size needs primitive geoms; {', '.join(bad)} is a mesh or plane")
    return geoms


@physics_target("object_size", ("geom_size", "geom_rbound", "geom_aabb", "bvh_aabb"), mujoco.mjtObj.mjOBJ_GEOM,
                ops=("scale",), select=_resizable, object_default=True)
def _apply_object_size(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    model.geom_size[idx] *= value[:, None]
    # The collision broad- and mid-phase cull with these bounds, fixed at compile time; stale
    # bounds miss contacts (a cube grown 5 % lost its finger-pad contacts now and then).
    model.geom_rbound[idx] *= value
    model.geom_aabb[idx, 3:] *= value[:, None]
    for geom, scale in zip(idx, value):
        body = model.geom_bodyid[geom]
        nodes = np.arange(model.body_bvhadr[body], model.body_bvhadr[body] + model.body_bvhnum[body])
        leaf = nodes[model.bvh_nodeid[nodes] == geom]
        model.bvh_aabb[leaf, 3:] *= scale
        # Inner nodes enclose other geoms too: they may grow with this one, never shrink.
        inner = nodes[model.bvh_nodeid[nodes] < 0]
        model.bvh_aabb[inner, 3:] *= max(scale, 1.0)


def _resolve(
    model: mujoco.MjModel,
    term: PhysicsTermSpec,
    object_geoms: Sequence[str],
    file: str | Path,
    path: str,
) -> np.ndarray:
    """Element indices a term applies to, or a `SpecError` naming the bad field."""
    target = PHYSICS_TARGETS.get(term.target)
    if target is None:
        raise SpecError.single(file, f"{path}.target", f"unknown physics target '{term.target}'; {expected_one_of(term.target, PHYSICS_TARGETS)}")
    if term.op not in target.ops:
        raise SpecError.single(file, f"{path}.op", f"{target.name} supports only {' or '.join(map(repr, target.ops))}")
    if target.element is None:
        if term.names:
            raise SpecError.single(file, f"{path}.names", f"{target.name} has no named elements; leave 'names' empty")
        return np.arange(3)

    kind = target.element
    names = [mujoco.mj_id2name(model, kind, i) or "" for i in range(_COUNT[kind](model))]
    patterns = [re.escape(g) for g in object_geoms] if target.object_default and not term.names else term.names
    chosen = [] if patterns or target.object_default else list(range(len(names)))  # no names: every element
    for j, pattern in enumerate(patterns):
        try:
            regex = re.compile(pattern)
        except re.error as exc:
            raise SpecError.single(file, f"{path}.names[{j}]", f"invalid regular expression: {exc}") from None
        hits = [i for i, n in enumerate(names) if n and regex.fullmatch(n)]
        if term.names and not hits:
            known = ", ".join(n for n in names if n)
            known = known if len(known) <= 200 else known[:200].rsplit(", ", 1)[0] + ", ..."
            raise SpecError.single(
                file, f"{path}.names[{j}]",
                f"'{pattern}' matches no {kind.name[6:].lower()} of the model; names include {known} "
                f"(every name: taskforge inspect {file})",
            )
        chosen += [i for i in hits if i not in chosen]
    if target.object_default and not chosen:
        raise SpecError.single(file, f"{path}.names", f"this environment has no main object geom for {target.name}; name the geoms in 'names'")
    chosen.sort()
    if target.select is not None:
        try:
            chosen = target.select(model, chosen)
        except ValueError as exc:
            raise SpecError.single(file, f"{path}.names", str(exc)) from None
    return np.array(chosen, dtype=int)
