"""JSON Schema of task, agent, curriculum and sweep files, from the same pydantic models the loader
validates with, so a YAML editor (e.g. VS Code's YAML extension, with `# yaml-language-server:
$schema=task.schema.json` at the top of a file) completes and checks fields exactly as
`taskforge validate` would. Registry names (reward terms, physics targets, features) are checked
in the loader's second pass; the schema shows them as strings."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel

from taskforge.spec.agent import AgentSpec
from taskforge.spec.curriculum import CurriculumSpec
from taskforge.spec.sweep import SweepSpec
from taskforge.spec.task import TaskSpec

Kind = Literal["task", "agent", "curriculum", "sweep"]
MODELS: dict[str, type[BaseModel]] = {"task": TaskSpec, "agent": AgentSpec, "curriculum": CurriculumSpec, "sweep": SweepSpec}


def json_schema(kind: Kind) -> dict[str, Any]:
    schema = MODELS[kind].model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}
