"""`taskforge render`: record episodes off-screen as a GIF or MP4.

MuJoCo picks its OpenGL backend when it is first imported, from `MUJOCO_GL`; importing
taskforge sets `osmesa` (software; Debian's `libosmesa6`) when there is no display and the user
chose nothing (`MUJOCO_GL=egl` is faster on a GPU machine).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import imageio.v2 as imageio
import mujoco
import numpy as np

from taskforge.agents import RL2Trial, wrap_for_training
from taskforge.backends import BACKENDS
from taskforge.demos import scripted_policy
from taskforge.envs import TaskEnv, load_task
from taskforge.run import load_run
from taskforge.spec import SpecError


@dataclass
class Actor:
    """What plays the rendered episodes: the env, `act(obs, episode_start) -> action`, and a few
    words on who acts, for the summary line."""

    env: TaskEnv | RL2Trial
    act: Callable[[np.ndarray, bool], np.ndarray]
    source: str


def scripted_actor(task_file: Path, stage: str | None, split: str) -> Actor:
    """A task file's scripted policy (the demonstrations' teacher) on one of its stages."""
    env = TaskEnv(load_task(task_file), task_file, stage=stage, split=split)
    policy = scripted_policy(env, stage)

    def act(obs: np.ndarray, start: bool) -> np.ndarray:
        if start:
            policy.reset(env)
        return policy(env)

    return Actor(env, act, f"scripted ({policy.name})")


def policy_actor(run_path: Path, stage: str | None, split: str) -> Actor:
    """A run's policy (`taskforge.run.load_run`) on a stage of its first phase (default: the
    phase's last stage), acting with its mean; for RL² an "episode" is a whole trial."""
    run = load_run(run_path)
    agent = run.agent
    task, task_file, stages = run.phases[0]
    env = TaskEnv(task, task_file, stage=stage or stages[-1], split=split, privileged=agent.privileged_dim > 0)
    state = agent.initial_state(1)

    def act(obs: np.ndarray, start: bool) -> np.ndarray:
        nonlocal state
        action, state = agent.act(obs[None], state, np.array([start]), deterministic=True)
        return action[0]

    return Actor(wrap_for_training(env, agent.spec), act, f"policy at step {agent.global_step:,}")


def _make_renderer(model: mujoco.MjModel, height: int, width: int, out: Path) -> mujoco.Renderer:
    """An off-screen renderer, or one clear line when this machine has no OpenGL to give it: the
    usual case is a headless machine without libOSMesa, where MuJoCo falls back to GLFW."""
    backend = os.environ.get("MUJOCO_GL", "").lower() or "glfw"
    hint = "install libOSMesa (Debian: apt install libosmesa6), or set MUJOCO_GL=egl on a GPU machine"
    if backend == "glfw" and not os.environ.get("DISPLAY"):  # GLFW needs a display; fail before it warns
        raise SpecError.single(out, "", f"no OpenGL for off-screen rendering: no display and no libOSMesa; {hint}")
    try:
        return mujoco.Renderer(model, height, width)
    except (mujoco.FatalError, RuntimeError) as exc:
        raise SpecError.single(out, "", f"no OpenGL context for rendering (MUJOCO_GL={backend}: {str(exc).splitlines()[0]}); {hint}") from None


def upright_frame(renderer: mujoco.Renderer, data: mujoco.MjData, camera: str | None) -> np.ndarray:
    """One frame from `camera` (None: the free camera) with the world's up at the top.

    A camera whose image "up" (its y axis) points down in the world renders the scene upside
    down: Meta-World's `corner` cameras are such, defined for mujoco-py, which read pixels
    bottom-up. Their frames are turned 180° (not flipped, which would mirror them)."""
    renderer.update_scene(data, camera=camera if camera is not None else -1)
    frame = renderer.render()
    if camera is not None:
        cam = mujoco.mj_name2id(renderer.model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if data.cam_xmat[cam][7] < 0:  # row-major 3x3: [7] is the z component of the y axis
            return frame[::-1, ::-1].copy()
    return frame.copy()


def render_episodes(
    env: TaskEnv | RL2Trial,
    act: Callable[[np.ndarray, bool], np.ndarray],
    out: Path,
    episodes: int = 1,
    seed: int = 0,
    camera: str | None = None,
    width: int = 320,
    height: int = 240,
    fps: int = 20,
    max_frames: int | None = None,
) -> tuple[int, list[bool]]:
    """Play `episodes` episodes with `act(obs, episode_start)` and write every control step as a
    frame. Returns the number of frames and each episode's success. For an RL² policy `env` is
    the `RL2Trial` around the `TaskEnv`: an "episode" is then a whole trial, and its success is
    that of the trial's last episode."""
    task_env: TaskEnv = env.unwrapped
    if task_env.backend.model(task_env.backend.task_names[0]) is None:
        raise SpecError.single(task_env.file, "backend.type", f"rendering needs a MuJoCo backend, not {task_env.task.backend.type}")
    if out.suffix.lower() not in (".gif", ".mp4"):
        raise SpecError.single(out, "", "expected an output file ending in .gif or .mp4")
    camera = camera or BACKENDS[task_env.task.backend.type].camera
    frames, successes = [], []
    renderer: mujoco.Renderer | None = None
    for k in range(episodes):
        obs, _ = env.reset(seed=seed + k)
        model = task_env.backend.model(task_env._episode["task"])
        if renderer is None or renderer.model is not model:
            renderer = _make_renderer(model, height, width, out)
            if camera is not None and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera) < 0:
                cams = [model.camera(i).name for i in range(model.ncam)]
                raise SpecError.single(task_env.file, "camera", f"no camera '{camera}'; expected one of {', '.join(cams)}")
        start, done, ever, info = True, False, False, {}
        while not done and (max_frames is None or len(frames) < max_frames):
            frames.append(upright_frame(renderer, task_env.backend.data, camera))
            obs, _, terminated, truncated, info = env.step(act(obs, start))
            start, done, ever = False, terminated or truncated, ever or info["success"]
        successes.append(bool(info["trial_successes"][-1]) if "trial_successes" in info else ever)
    out.parent.mkdir(parents=True, exist_ok=True)
    if out.suffix.lower() == ".gif":
        imageio.mimsave(out, frames, duration=1000 / fps, loop=0)
    else:
        imageio.mimsave(out, frames, fps=fps, macro_block_size=1)
    return len(frames), successes
