"""taskforge: curriculum and meta-RL for robot manipulation, with tasks written once in YAML.

Public API (stable):
    taskforge.make(task_file, stage=..., split=..., seed=...)  -> gymnasium.Env
    taskforge.load_task(path) / load_curriculum(path)          -> validated specs
    taskforge.SpecError                                        -> every user mistake
"""

from taskforge.envs import TaskEnv, load_curriculum, load_task, make
from taskforge.spec import SpecError, load_agent_spec

__version__ = "0.1.0"

__all__ = ["SpecError", "TaskEnv", "load_agent_spec", "load_curriculum", "load_task", "make"]
