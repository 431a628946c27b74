"""The authoring guide and `taskforge schema` come from the same pydantic models: every field of a
task, agent, curriculum or sweep file has a row in docs/authoring.md, and the exported JSON Schema is
the models' own, so the guide, the schema and the loader cannot drift apart."""

from __future__ import annotations

import json
import re
import typing

import pytest
from pydantic import BaseModel

from taskforge.cli import main
from taskforge.spec import AgentSpec, CurriculumSpec, SweepSpec, TaskSpec
from tests.conftest import ROOT

GUIDE = (ROOT / "docs/authoring.md").read_text()
ROWS = {m.group(1): m.group(0) for m in re.finditer(r"^\|\s*`([A-Za-z_][A-Za-z0-9_.\[\]]*)`[^\n]*", GUIDE, re.M)}
"""First cell of every table row (a field name, possibly dotted) -> the whole row."""


def _models(annotation) -> list[type[BaseModel]]:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in typing.get_args(annotation) for m in _models(arg)]


def _fields(model: type[BaseModel], parent: str | None = None, seen: set | None = None):
    """(model, field, parent field) for every field reachable from `model`."""
    seen = set() if seen is None else seen
    if model in seen:
        return
    seen.add(model)
    for name, info in model.model_fields.items():
        yield model, name, parent
        for sub in _models(info.annotation):
            yield from _fields(sub, name, seen)


def _documented(name: str, parent: str | None) -> bool:
    """A row of its own (`name`, or dotted: `parent.name`, `name.child`), or named inside its
    parent's row (small records such as `{x: [low, high], y: ...}` are documented in one row)."""
    if any(name in label.split(".") for label in ROWS):
        return True
    parent_rows = [row for label, row in ROWS.items() if parent is not None and label.split(".")[-1] == parent]
    return any(re.search(rf"\b{re.escape(name)}\b\s*:", row) for row in parent_rows)


@pytest.mark.parametrize("root", [TaskSpec, AgentSpec, CurriculumSpec, SweepSpec], ids=lambda m: m.__name__)
def test_every_field_has_a_row_in_the_authoring_guide(root):
    missing = [f"{model.__name__}.{name}" for model, name, parent in _fields(root) if not _documented(name, parent)]
    assert not missing, f"fields without a row in docs/authoring.md: {', '.join(missing)}"


@pytest.mark.parametrize("kind,model", [("task", TaskSpec), ("agent", AgentSpec), ("curriculum", CurriculumSpec),
                                        ("sweep", SweepSpec)])
def test_schema_prints_the_models_json_schema(kind, model, capsys):
    assert main(["schema", kind]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["title"] == model.__name__ and schema["properties"].keys() == model.model_json_schema()["properties"].keys()
    assert schema["$schema"].startswith("https://json-schema.org/")


def test_schema_writes_a_file_and_rejects_an_unknown_kind(tmp_path, capsys):
    out = tmp_path / "task.schema.json"
    assert main(["schema", "task", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["title"] == "TaskSpec"
    with pytest.raises(SystemExit):
        main(["schema", "tasks"])
    assert "invalid choice: 'tasks'" in capsys.readouterr().err
