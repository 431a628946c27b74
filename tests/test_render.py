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

pytestmark = pytest.mark.skipif(
    ctypes.util.find_library("OSMesa") is None, reason="libOSMesa not installed (Debian: libosmesa6; .ci/run installs it)"
)


def render(tmp_path, *args: str) -> tuple[subprocess.CompletedProcess, list[np.ndarray]]:
    out = tmp_path / "video.gif"
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    proc = subprocess.run([sys.executable, "-m", "taskforge.cli", "render", *args, "--out", str(out)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    return proc, (imageio.mimread(out) if out.exists() else [])


@pytest.mark.parametrize("task,stage", [("tasks/xarm7/reach.yaml", "reach"), ("tasks/metaworld/pick_place.yaml", "reach")])
def test_render_scripted_episode_frames_are_not_blank(tmp_path, task, stage):
    proc, frames = render(tmp_path, task, "--stage", stage, "--max-frames", "6", "--width", "96", "--height", "72")
    assert proc.returncode == 0, proc.stderr
    assert len(frames) == 6 and frames[0].shape[:2] == (72, 96)
    for frame in frames:
        assert frame[..., :3].std() > 10  # a scene, not a flat colour
    assert not np.array_equal(frames[0], frames[-1])  # the robot moved


def test_render_rejects_a_bad_camera_and_output(tmp_path):
    proc, _ = render(tmp_path, "tasks/xarm7/reach.yaml", "--camera", "nope", "--max-frames", "2")
    assert proc.returncode == 2 and "no camera 'nope'" in proc.stderr and "Traceback" not in proc.stderr
