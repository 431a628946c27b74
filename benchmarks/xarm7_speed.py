"""xArm7 speed: IK time per control step, and env steps/s against raw `mj_step` of the same model.

    python benchmarks/xarm7_speed.py [--steps 1500] [--repeats 3]

Rows: the full env (`tasks/xarm7/pick_place.yaml`, Cartesian control with mink IK, full
randomisation, first stage's terms), the joint-position variant (`reach_joint.yaml`, no IK), and
"raw": the same
compiled model stepped with `mj_step` x substeps per control step, replaying the controls the
Cartesian env produced (so the physics work is the same and only the IK + env layers differ).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import taskforge  # noqa: E402
from benchmarks.common import print_table, versions, write_result  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def run_env(task: str, actions: np.ndarray, seed: int) -> tuple[float, float, np.ndarray]:
    """(steps/s, IK ms per control step, the controls written to the model each step)."""
    env = taskforge.make(ROOT / task, seed=seed)  # the task's first stage
    env.reset()
    backend = env.backend
    ik = getattr(backend, "ik", None)
    if ik is not None:
        ik.total_time, ik.calls = 0.0, 0
    controls = np.zeros((len(actions), backend.model(backend.task_names[0]).nu))
    start = time.perf_counter()
    for i, action in enumerate(actions[:, : env.action_space.shape[0]]):
        *_, terminated, truncated, _ = env.step(action)
        controls[i] = backend.data.ctrl
        if terminated or truncated:
            env.reset()
    sps = len(actions) / (time.perf_counter() - start)
    ik_ms = ik.ms_per_call if (ik is not None and backend.cartesian) else float("nan")
    return sps, ik_ms, controls


def run_raw(controls: np.ndarray, substeps: int) -> float:
    env = taskforge.make(ROOT / "tasks/xarm7/pick_place.yaml", stage="place", seed=0)
    env.reset()
    m, d = env.backend.model(env.backend.task_names[0]), env.backend.data
    start = time.perf_counter()
    for ctrl in controls:
        d.ctrl[:] = ctrl
        mujoco.mj_step(m, d, nstep=substeps)
    return len(controls) / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    actions = np.random.default_rng(0).uniform(-1, 1, (args.steps, 8)).astype(np.float32)
    substeps = taskforge.make(ROOT / "tasks/xarm7/pick_place.yaml").backend.substeps
    cart, joint, raw, ik = [], [], [], []
    for r in range(args.repeats):
        sps, ik_ms, controls = run_env("tasks/xarm7/pick_place.yaml", actions, r)
        cart.append(sps)
        ik.append(ik_ms)
        joint.append(run_env("tasks/xarm7/reach_joint.yaml", actions, r)[0])
        raw.append(run_raw(controls, substeps))
    med = {k: statistics.median(v) for k, v in {"cartesian": cart, "joint": joint, "raw": raw, "ik_ms": ik}.items()}
    print_table(["what", "median", "runs"], [
        ["raw mj_step x substeps (control steps/s)", med["raw"], ", ".join(f"{x:.0f}" for x in raw)],
        ["xArm7 env, Cartesian + mink IK (steps/s)", med["cartesian"], ", ".join(f"{x:.0f}" for x in cart)],
        ["xArm7 env, joint targets (steps/s)", med["joint"], ", ".join(f"{x:.0f}" for x in joint)],
        ["IK time per control step (ms)", f"{med['ik_ms']:.3f}", ", ".join(f"{x:.3f}" for x in ik)],
    ])
    print(f"Cartesian env = {med['cartesian'] / med['raw']:.2f} x raw; joint env = {med['joint'] / med['raw']:.2f} x raw; "
          f"{substeps} physics substeps per control step")
    write_result("xarm7_speed", {"steps": args.steps, "repeats": args.repeats, "substeps": substeps,
                                 "raw_control_steps_per_s": raw, "cartesian_steps_per_s": cart, "joint_steps_per_s": joint,
                                 "ik_ms_per_control_step": ik, "medians": med,
                                 "versions": versions("mujoco", "mink", "qpsolvers", "daqp")})


if __name__ == "__main__":
    main()
