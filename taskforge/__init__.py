"""taskforge: curriculum and meta-RL for robot manipulation, with tasks written once in YAML.

Public API (stable):
    taskforge.make(task_file, stage=..., split=..., seed=...)  -> gymnasium.Env
    taskforge.load_task(path) / load_curriculum(path)          -> validated specs
    taskforge.SpecError                                        -> every user mistake
"""

import os

_LIBRARY_DIRS = ("/usr/lib", "/usr/lib64", "/usr/local/lib", "/lib", "/lib64", "/usr/lib/x86_64-linux-gnu",
                 "/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/lib/aarch64-linux-gnu")


def _has_osmesa() -> bool:
    """libOSMesa in LD_LIBRARY_PATH or a system library directory. A directory scan rather than
    `ctypes.util.find_library`, which costs tens of milliseconds (ctypes, an `ldconfig` call) at
    every `import taskforge`, the window in which a Ctrl-C would still print a traceback."""
    dirs = [d for d in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if d] + list(_LIBRARY_DIRS)
    for directory in dirs:
        try:
            with os.scandir(directory) as entries:
                if any(e.name.startswith("libOSMesa.so") for e in entries):
                    return True
        except OSError:
            continue
    return False


# MuJoCo chooses its OpenGL backend once, when first imported. Without a display, its default
# (GLFW) cannot render at all; software OSMesa (Debian's libosmesa6) works everywhere it is
# installed. Only then is it chosen: with MUJOCO_GL=osmesa and no libOSMesa, `import mujoco`
# itself fails, and training needs no OpenGL at all. A user who set MUJOCO_GL (e.g. egl on a
# GPU machine) keeps their choice.
if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY") and _has_osmesa():
    os.environ["MUJOCO_GL"] = "osmesa"
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

__version__ = "0.1.0"

__all__ = ["SpecError", "TaskEnv", "load_agent_spec", "load_curriculum", "load_task", "make"]

# The public names load on first use (PEP 562), so `import taskforge` costs nothing and the
# command line can catch a Ctrl-C during the heavy imports (torch, MuJoCo) that follow.
_PUBLIC = {"TaskEnv": "taskforge.envs", "load_curriculum": "taskforge.envs", "load_task": "taskforge.envs",
           "make": "taskforge.envs", "SpecError": "taskforge.spec", "load_agent_spec": "taskforge.spec"}


def __getattr__(name: str):
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'taskforge' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_PUBLIC])
