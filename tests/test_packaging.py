"""taskforge installs as a library: a built wheel carries the built-in xArm7 model and
`py.typed`, and the installed package finds the model without this repository."""

from __future__ import annotations

import subprocess
import sys
import zipfile

import pytest

from tests.conftest import ROOT


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheel")
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out), str(ROOT)],
                           capture_output=True, text=True)
    if build.returncode != 0:
        pytest.skip(f"cannot build a wheel here: {build.stderr.strip().splitlines()[-1:]}")
    return next(out.glob("taskforge-*.whl"))


def test_the_wheel_carries_the_xarm7_model_and_py_typed(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {"taskforge/py.typed", "taskforge/backends/assets/xarm7/xarm7.xml", "taskforge/backends/assets/xarm7/scene.xml"} <= names
    assert not any(n.startswith(("tests/", "benchmarks/", "tasks/")) for n in names)


def test_an_installed_copy_builds_the_xarm7_scene_from_its_own_files(wheel, tmp_path):
    """Unpacked elsewhere (as pip would install it), away from this checkout."""
    zipfile.ZipFile(wheel).extractall(tmp_path / "site")
    site = str(tmp_path / "site")
    code = ("import taskforge.backends.xarm7_scene as s, mujoco; "
            f"assert str(s.BUILTIN_ROBOT).startswith({site!r}), s.BUILTIN_ROBOT; "
            "print(mujoco.MjModel.from_xml_path(str(s.BUILTIN_ROBOT)).njnt)")
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": site, "PATH": "/usr/bin:/bin"})
    assert run.returncode == 0, run.stderr
    assert int(run.stdout.strip()) >= 9  # 7 arm joints and the gripper's
