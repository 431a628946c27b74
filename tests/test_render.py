"""Off-screen rendering writes real, non-blank frames (OSMesa; skipped where it is missing)."""

from __future__ import annotations

import ctypes.util
import os
import subprocess
import sys

import imageio.v2 as imageio
import numpy as np
import pytest

from tests.conftest import ROOT

needs_osmesa = pytest.mark.skipif(
    ctypes.util.find_library("OSMesa") is None, reason="libOSMesa not installed (Debian: libosmesa6; .ci/run installs it)"
)


def render(tmp_path, *args: str, **env_extra: str) -> tuple[subprocess.CompletedProcess, list[np.ndarray]]:
    out = tmp_path / "video.gif"
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")} | env_extra
    proc = subprocess.run([sys.executable, "-m", "taskforge.cli", "render", *args, "--out", str(out)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    return proc, (imageio.mimread(out) if out.exists() else [])


@needs_osmesa
@pytest.mark.parametrize("task,stage", [("tasks/xarm7/reach.yaml", "reach"), ("tasks/metaworld/pick_place.yaml", "reach")])
def test_render_scripted_episode_frames_are_not_blank(tmp_path, task, stage):
    proc, frames = render(tmp_path, task, "--stage", stage, "--max-frames", "6", "--width", "96", "--height", "72")
    assert proc.returncode == 0, proc.stderr
    assert len(frames) == 6 and frames[0].shape[:2] == (72, 96)
    for frame in frames:
        assert frame[..., :3].std() > 10  # a scene, not a flat colour
    assert not np.array_equal(frames[0], frames[-1])  # the robot moved


@needs_osmesa
def test_render_rejects_a_bad_camera_and_output(tmp_path):
    proc, _ = render(tmp_path, "tasks/xarm7/reach.yaml", "--camera", "nope", "--max-frames", "2")
    assert proc.returncode == 2 and "no camera 'nope'" in proc.stderr and "Traceback" not in proc.stderr


@needs_osmesa
def test_render_an_rl2_run_plays_a_whole_trial(tmp_path):
    """An RL² policy needs the augmented observation: render wraps the env in trials, so one
    rendered "episode" is K = 2 episodes of reach (2 x 30 steps) and the policy runs through the
    inner reset."""
    import yaml

    from taskforge.training import train

    task = yaml.safe_load((ROOT / "tasks/metaworld/reach.yaml").read_text())
    task["max_episode_steps"] = 30
    (tmp_path / "task.yaml").write_text(yaml.safe_dump(task))
    agent = {"name": "tiny-rl2", "algo": "rl2", "rl2": {"trial_episodes": 2},
             "policy": {"type": "gru", "recurrent_size": 8, "hidden_sizes": [8]},
             "ppo": {"num_envs": 1, "rollout_steps": 30, "num_minibatches": 1, "update_epochs": 1},
             "runtime": {"vector": "sync"}}
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(agent))
    (tmp_path / "cur.yaml").write_text(yaml.safe_dump(
        {"name": "tiny", "agent": "agent.yaml", "total_steps": 30, "phases": [{"task": "task.yaml"}]}))
    run = train(tmp_path / "cur.yaml", run_dir=tmp_path / "run", progress=False)
    proc, frames = render(tmp_path, str(run), "--width", "64", "--height", "48")
    assert proc.returncode == 0, proc.stderr
    assert len(frames) == 60 and ("success 0/1" in proc.stdout or "success 1/1" in proc.stdout), proc.stdout


def test_render_without_opengl_says_so_in_one_line(tmp_path):
    """A headless machine without libOSMesa: MuJoCo falls back to GLFW, which cannot open a
    context; render must say what to install instead of crashing inside MuJoCo."""
    proc, frames = render(tmp_path, "tasks/xarm7/reach.yaml", "--max-frames", "2", MUJOCO_GL="glfw")
    assert proc.returncode == 2 and frames == [], proc.stderr
    assert proc.stderr.count("\n") == 1 and "libosmesa6" in proc.stderr and "Traceback" not in proc.stderr


ORIENTATION = """
import json, sys
import taskforge  # first: it chooses MuJoCo's OpenGL backend (OSMesa without a display)
import mujoco, numpy as np
from taskforge.envs import TaskEnv, load_task
from taskforge.rendering import upright_frame
out = {}
for task_file, camera in json.loads(sys.argv[1]):
    env = TaskEnv(load_task(task_file), task_file, stage="reach")
    env.reset(seed=0)
    name = env.backend.task_names[0]
    model, data = env.backend.model(name), env.backend.data
    body = model.geom_bodyid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, env.backend.object_geoms(name)[0])]
    z = model.jnt_qposadr[model.body_jntadr[body]] + 2  # the object's free joint: x, y, z, quaternion
    renderer = mujoco.Renderer(model, 120, 160)

    def frame(height):  # the object at `height` above where it rests (or out of sight)
        data.qpos[z] += height
        mujoco.mj_forward(model, data)
        image = upright_frame(renderer, data, camera).astype(int)
        data.qpos[z] -= height
        return image

    empty = frame(-50.0)
    rows = [np.nonzero(np.abs(frame(h) - empty).sum(-1) > 30)[0].mean() for h in (0.0, 0.15)]
    out[f"{task_file}:{camera}"] = rows[1] - rows[0]  # image rows grow downwards
    renderer.close()  # one OSMesa context at a time
    env.close()
print(json.dumps(out))
"""


@needs_osmesa
def test_frames_are_upright():
    """Lift the object 15 cm: it must move up in the frame. Meta-World's `corner` cameras point
    their image "up" at the floor; without the turn every Meta-World render had the table on top."""
    import json

    views = [("tasks/metaworld/pick_place.yaml", "corner"), ("tasks/metaworld/pick_place.yaml", "corner2"),
             ("tasks/metaworld/pick_place.yaml", "behindGripper"), ("tasks/xarm7/reach.yaml", "front")]
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    proc = subprocess.run([sys.executable, "-c", ORIENTATION, json.dumps(views)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    for view, moved in json.loads(proc.stdout.strip().splitlines()[-1]).items():
        assert moved < -3, f"{view}: the lifted object moved {moved:+.1f} rows (down the frame: upside down)"
