"""Cartesian control of the xArm7: mink differential IK from a TCP target to arm joint targets.

Each control step solves for joint *targets* (written to the position servos), warm-started from
the previous step's solution, with the gripper pointing straight down (fingers closing along
world y, the orientation at `home`):

* a `FrameTask` on the `link_tcp` site (position cost 1, orientation cost
  `control.orientation_cost`, Levenberg-Marquardt damping `control.ik_damping`);
* a `PostureTask` towards `home` (cost `control.posture_cost`) for the redundant joint;
* a `ConfigurationLimit` (the joint ranges).

One iteration is one QP built by `mink.build_ik` and solved by daqp (what `mink.solve_ik` does,
without its per-call Python loop over the joint limits, which only logs); it integrates the
solution with a unit step (`dt = 1`, a Gauss-Newton step). At most `control.ik_iterations` per
control step (default 1, mink's usual one differential-IK step per control tick); it stops as
soon as the position error is below `control.ik_tolerance_m` (and the orientation error below
10x that in rad), so a held target costs no QP at all.

Cost: mink builds each QP in Python; its `FrameTask` objective (the SE(3) log and its
Jacobian) is most of the ~0.5 ms an iteration takes, about as much as 20 `mj_step`s of this
scene. `solve` accumulates its wall time in `total_time` / `calls`
(`XArm7Backend.ik_ms_per_step`).

IK runs on a separate, kinematics-only model of the robot (`xarm7_scene.build_ik_model`, 7
dofs): physics randomisation of the scene model never changes kinematics, and the QP does not
carry the gripper's or the cube's dofs.
"""

from __future__ import annotations

import math
import time

import mink
import mujoco
import numpy as np
import qpsolvers

from taskforge.backends.xarm7_scene import ARM_JOINTS, TCP_SITE

R_DOWN = np.array([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
"""`link_tcp` orientation with the gripper pointing straight down, fingers closing along
world y (the orientation at the `home` keyframe)."""


class CartesianIK:
    """mink IK of `link_tcp` on the arm-only model; `solve(target)` -> 7 joint targets."""

    def __init__(self, ik_model: mujoco.MjModel, home: np.ndarray, *, iterations: int, tolerance: float,
                 damping: float, orientation_cost: float, posture_cost: float):
        self.model = ik_model
        self._qadr = np.array([ik_model.jnt_qposadr[ik_model.joint(j).id] for j in ARM_JOINTS])
        assert ik_model.nq == ik_model.nv == len(ARM_JOINTS), "the IK model has exactly the arm's 7 dofs"
        self.configuration = mink.Configuration(ik_model)
        self.frame = mink.FrameTask(TCP_SITE, "site", position_cost=1.0, orientation_cost=orientation_cost,
                                    lm_damping=damping)
        self.posture = mink.PostureTask(ik_model, cost=posture_cost)
        self.limits = [mink.ConfigurationLimit(ik_model)]
        self.tasks = [self.frame, self.posture] if posture_cost > 0 else [self.frame]
        self.iterations = iterations
        self.tolerance = tolerance
        self.damping = damping
        self._home_q = self._full_q(home)
        self.posture.set_target(self._home_q)
        self._site = ik_model.site(TCP_SITE).id
        self._rotation = mink.SO3.from_matrix(R_DOWN)
        self.total_time = 0.0
        """Seconds spent in `solve` since construction (for benchmarks)."""
        self.calls = 0
        self.qp_solves = 0

    def _full_q(self, arm_q: np.ndarray) -> np.ndarray:
        q = self.model.qpos0.copy()
        q[self._qadr] = arm_q
        return q

    def reset(self, arm_q: np.ndarray) -> None:
        """Warm start from these joint angles (the arm's actual configuration at reset)."""
        self.configuration.update(self._full_q(arm_q))

    def tcp(self) -> np.ndarray:
        """TCP position of the current solution (forward kinematics of the IK model)."""
        return self.configuration.data.site_xpos[self._site].copy()

    def solve(self, target: np.ndarray, iterations: int | None = None) -> np.ndarray:
        """Joint angles that put `link_tcp` at `target` pointing down; starts from the previous
        solution. Returns a view of the arm angles (copy it to keep it)."""
        start = time.perf_counter()
        cfg = self.configuration
        data = cfg.data
        self.frame.set_target(mink.SE3.from_rotation_and_translation(self._rotation, target))
        tx, ty, tz = float(target[0]), float(target[1]), float(target[2])
        tol = self.tolerance
        for _ in range(self.iterations if iterations is None else iterations):
            px, py, pz = data.site_xpos[self._site].tolist()
            if math.dist((px, py, pz), (tx, ty, tz)) < tol and _orientation_error(data.site_xmat[self._site]) < 10 * tol:
                break
            problem = mink.build_ik(cfg, self.tasks, 1.0, self.damping, self.limits)
            result = qpsolvers.solve_problem(problem, solver="daqp")
            if not result.found:  # keep the last solution; the servo holds it
                break
            cfg.integrate_inplace(result.x, 1.0)
            self.qp_solves += 1
        self.total_time += time.perf_counter() - start
        self.calls += 1
        return cfg.q[self._qadr]

    @property
    def ms_per_call(self) -> float:
        return 1e3 * self.total_time / max(self.calls, 1)


def _orientation_error(xmat: np.ndarray) -> float:
    """Angle (rad, small-angle approximation) between the site's frame and `R_DOWN`: with
    R_DOWN = diag(-1, 1, -1), trace(R_DOWN^T R) = -R00 + R11 - R22 = 1 + 2 cos(angle)."""
    r00, _, _, _, r11, _, _, _, r22 = xmat.tolist()
    c = max(-1.0, min(1.0, (-r00 + r11 - r22 - 1.0) * 0.5))
    return math.acos(c)
