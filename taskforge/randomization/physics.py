"""Physics randomisation of a compiled MuJoCo model, in the style of the *Learning Dexterity*
table (OpenAI et al., 2019): masses, friction, joint damping, actuator gains, gravity and object
size, each scaled or offset by a draw at every reset.

Why snapshot-and-restore: every draw starts from the nominal model, so values never drift
episode after episode, and `restore()` gives the exact nominal model back.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from taskforge.randomization.distributions import sample
from taskforge.spec import PhysicsTermSpec, SpecError, SpecIssue

# Which model arrays each target touches; they are snapshotted once and restored before draws.
_ARRAYS: dict[str, tuple[str, ...]] = {
    "body_mass": ("body_mass", "body_inertia"),
    "geom_friction": ("geom_friction",),
    "dof_damping": ("dof_damping",),
    "actuator_gain": ("actuator_gainprm", "actuator_biasprm"),
    "gravity": ("opt.gravity",),
    "object_size": ("geom_size", "geom_rbound", "geom_aabb", "bvh_aabb"),
}
_NAMED_OBJ = {
    "body_mass": mujoco.mjtObj.mjOBJ_BODY,
    "geom_friction": mujoco.mjtObj.mjOBJ_GEOM,
    "dof_damping": mujoco.mjtObj.mjOBJ_JOINT,
    "actuator_gain": mujoco.mjtObj.mjOBJ_ACTUATOR,
    "object_size": mujoco.mjtObj.mjOBJ_GEOM,
}
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
            for name in _ARRAYS[term.spec.target]
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
            _APPLY[spec.target](self.model, index, value, spec.op)
            draws.append(value)
        self.last_draw = np.concatenate(draws) if draws else np.zeros(0)
        return self.last_draw


def _array(model: mujoco.MjModel, name: str) -> np.ndarray:
    return model.opt.gravity if name == "opt.gravity" else getattr(model, name)


def _combine(nominal: np.ndarray, value: np.ndarray, op: str) -> np.ndarray:
    return nominal * value if op == "scale" else nominal + value


def _apply_body_mass(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    old = model.body_mass[idx].copy()
    # A body must keep a positive mass; a draw may not take it below a thousandth of nominal.
    new = np.maximum(_combine(old, value, op), old * 1e-3)
    model.body_mass[idx] = new
    # Inertia scales with mass for a fixed shape; keeps the model physically consistent.
    model.body_inertia[idx] *= (new / np.where(old > 0, old, 1.0))[:, None]


def _apply_friction(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    model.geom_friction[idx] = np.maximum(_combine(model.geom_friction[idx], value[:, None], op), 0.0)


def _apply_damping(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    model.dof_damping[idx] = np.maximum(_combine(model.dof_damping[idx], value, op), 0.0)


def _apply_actuator_gain(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    old = model.actuator_gainprm[idx, 0].copy()
    new = _combine(old, value, op)
    model.actuator_gainprm[idx, 0] = new
    # A position servo's bias is (0, -kp, -kv): scale it with kp or the servo's set point moves.
    ratio = new / np.where(old != 0, old, 1.0)
    model.actuator_biasprm[idx, 1:3] *= ratio[:, None]


def _apply_gravity(model: mujoco.MjModel, idx: np.ndarray, value: np.ndarray, op: str) -> None:
    model.opt.gravity[idx] = _combine(model.opt.gravity[idx], value, op)


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


_APPLY = {
    "body_mass": _apply_body_mass,
    "geom_friction": _apply_friction,
    "dof_damping": _apply_damping,
    "actuator_gain": _apply_actuator_gain,
    "gravity": _apply_gravity,
    "object_size": _apply_object_size,
}


def _resolve(
    model: mujoco.MjModel,
    term: PhysicsTermSpec,
    object_geoms: Sequence[str],
    file: str | Path,
    path: str,
) -> np.ndarray:
    """Element indices a term applies to, or a `SpecError` naming the bad field."""
    if term.target == "gravity":
        if term.names:
            raise SpecError.single(file, f"{path}.names", "gravity has no named elements; leave 'names' empty")
        return np.arange(3)
    if term.target == "object_size" and term.op != "scale":
        raise SpecError.single(file, f"{path}.op", "object_size supports only 'scale'")

    kind = _NAMED_OBJ[term.target]
    count = {
        "body_mass": model.nbody, "geom_friction": model.ngeom, "dof_damping": model.njnt,
        "actuator_gain": model.nu, "object_size": model.ngeom,
    }[term.target]
    names = [mujoco.mj_id2name(model, kind, i) or "" for i in range(count)]
    if term.target == "object_size" and not term.names:
        patterns = [re.escape(g) for g in object_geoms]
    else:
        patterns = term.names
    if not patterns and term.target != "object_size":
        chosen = list(range(count))  # no names: every element, named or not
    else:
        chosen = []
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
                f"'{pattern}' matches no {kind.name[6:].lower()} of the model; names include {known}",
            )
        chosen += [i for i in hits if i not in chosen]
    if term.target == "body_mass":
        chosen = [i for i in chosen if i > 0 and model.body_mass[i] > 0]  # the world has no mass
    if term.target == "object_size":
        if not chosen:
            raise SpecError.single(file, f"{path}.names", "this environment has no main object geom to resize; name the geoms in 'names'")
        bad = [names[i] for i in chosen if model.geom_type[i] not in _RESIZABLE_GEOMS]
        if bad:
            raise SpecError.single(file, f"{path}.names", f"object_size needs primitive geoms; {', '.join(bad)} is a mesh or plane")
    index = np.array(sorted(chosen), dtype=int)
    if term.target == "dof_damping":
        index = _joint_dofs(model, index)
    return index


def _joint_dofs(model: mujoco.MjModel, joints: np.ndarray) -> np.ndarray:
    """Joint ids -> the dof ids they own (a free joint has 6, a ball 3, hinge/slide 1)."""
    width = {mujoco.mjtJoint.mjJNT_FREE: 6, mujoco.mjtJoint.mjJNT_BALL: 3}
    dofs = [
        model.jnt_dofadr[j] + k
        for j in joints
        for k in range(width.get(model.jnt_type[j], 1))
    ]
    return np.array(dofs, dtype=int)
