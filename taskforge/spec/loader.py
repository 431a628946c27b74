"""Reading YAML files into schema models, with every mistake reported as file + field path."""

from __future__ import annotations

import os
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from taskforge.spec.agent import AgentSpec
from taskforge.spec.backends import BACKEND_TYPES
from taskforge.spec.curriculum import CurriculumSpec
from taskforge.spec.errors import SpecError, issues_from_validation
from taskforge.spec.sweep import SweepSpec
from taskforge.spec.task import TaskSpec

M = TypeVar("M", bound=BaseModel)


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Parse a YAML mapping; a missing file or bad syntax is a `SpecError`, not a traceback."""
    path = Path(path)
    if not path.is_file():
        what = "is a directory" if path.is_dir() else "no such file"
        raise SpecError.single(path, "", f"{what}; expected a YAML file")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "?"
        raise SpecError.single(path, "", f"invalid YAML at {where}: {exc.problem}") from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise SpecError.single(path, "", f"invalid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise SpecError.single(path, "", f"expected a mapping at the top level, got {type(data).__name__}")
    return data


def validate(model: type[M], data: dict[str, Any], file: str | Path) -> M:
    """Validate `data` against `model`; collect every mistake into one `SpecError`."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        issues = issues_from_validation(
            exc, file, allowed_keys=lambda loc: field_names_at(model, loc), union_tags=BACKEND_TYPES
        )
        raise SpecError(issues) from None


# Fields that hold paths (relative to the file that writes them); "*" stands for every item of a list.
_TASK_PATH_FIELDS: tuple[tuple[str, ...], ...] = (("backend", "robot_model"),)
_CURRICULUM_PATH_FIELDS: tuple[tuple[str, ...], ...] = (("agent",), ("phases", "*", "task"), ("warm_start", "demos"), ("init_from",))
_SWEEP_PATH_FIELDS: tuple[tuple[str, ...], ...] = (("curriculum",),)


def read_yaml_with_base(
    path: str | Path, path_fields: tuple[tuple[str, ...], ...] = (), _chain: tuple[Path, ...] = ()
) -> dict[str, Any]:
    """A task, agent or curriculum file's mapping merged over the file its `base:` names (bases
    may have bases).

    Why: a variant (a bigger cube, the object drawn per trial, an agent with longer BPTT) differs
    from its base in a field or two. Writing only those keeps the variant in step with its base
    instead of a copy that drifts. Mappings merge key by key; anything else the variant writes
    (a list such as `stages`, a number, null) replaces the base's value whole, so a variant
    that changes one stage restates the `stages` list. Paths at `path_fields` in the base are
    rewritten to name the same files from the variant's folder.
    """
    path = Path(path)
    data = read_yaml(path)
    if "base" not in data:
        return data
    ref = data.pop("base")
    if not isinstance(ref, str) or not ref.strip():
        raise SpecError.single(path, "base", f"expected the path of a file of the same kind, relative to this one (got {ref!r})")
    base_path = resolve_relative(path, ref)
    chain = (*_chain, path.resolve())
    if base_path.resolve() in chain:
        raise SpecError.single(path, "base", f"'{ref}' leads back to this file; expected a chain of bases that ends")
    if not base_path.is_file():
        raise SpecError.single(path, "base", f"no such file {base_path}; expected a file of the same kind, relative to this one")
    base = read_yaml_with_base(base_path, path_fields, chain)
    for field in path_fields:
        _rebase_path(base, field, base_path, path)
    return _merge(base, data)


def read_task_yaml(path: str | Path) -> dict[str, Any]:
    """A task file's mapping with its `base:` chain merged in (see `read_yaml_with_base`)."""
    return read_yaml_with_base(path, _TASK_PATH_FIELDS)


def read_curriculum_yaml(path: str | Path) -> dict[str, Any]:
    """A curriculum file's mapping with its `base:` chain merged in, every path relative to `path`."""
    return read_yaml_with_base(path, _CURRICULUM_PATH_FIELDS)


def _rebase_path(data: Any, field: tuple[str, ...], old_file: Path, new_file: Path) -> None:
    """Rewrite a relative path at `field` so that it names the same file from `new_file`'s folder.
    Anything not shaped as `field` expects is left for schema validation to report."""
    head, *rest = field
    if head == "*":
        for item in data if isinstance(data, list) else ():
            _rebase_path(item, tuple(rest), old_file, new_file)
        return
    if not isinstance(data, dict):
        return
    if rest:
        _rebase_path(data.get(head), tuple(rest), old_file, new_file)
        return
    value = data.get(head)
    if isinstance(value, str) and not Path(value).is_absolute():
        data[head] = os.path.relpath(resolve_relative(old_file, value), new_file.parent)


def _merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """`override` over `base`: mappings merge recursively, any other value replaces."""
    merged = dict(base)
    for key, value in override.items():
        both_maps = isinstance(value, dict) and isinstance(base.get(key), dict)
        merged[key] = _merge(base[key], value) if both_maps else value
    return merged


def load_task_spec(path: str | Path) -> TaskSpec:
    return validate(TaskSpec, read_task_yaml(path), path)


def load_agent_spec(path: str | Path) -> AgentSpec:
    return validate(AgentSpec, read_yaml_with_base(path), path)


def load_curriculum_spec(path: str | Path) -> CurriculumSpec:
    return validate(CurriculumSpec, read_yaml_with_base(path, _CURRICULUM_PATH_FIELDS), path)


def load_sweep_spec(path: str | Path) -> SweepSpec:
    return validate(SweepSpec, read_yaml_with_base(path, _SWEEP_PATH_FIELDS), path)


def resolve_relative(base_file: str | Path, ref: str) -> Path:
    """A path written inside a YAML file is relative to that file, like an `#include`."""
    ref_path = Path(ref)
    return ref_path if ref_path.is_absolute() else Path(os.path.normpath(Path(base_file).parent / ref_path))


def field_names_at(model: type[BaseModel], loc: tuple[str | int, ...]) -> list[str]:
    """The keys a user may write at `loc` inside `model` (used for 'did you mean' hints)."""
    annotation: Any = model
    for part in loc:
        annotation = _step(annotation, part)
        if annotation is None:
            return []
    annotation = _unwrap_optional(annotation)
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return list(annotation.model_fields)
    return []


def _step(annotation: Any, part: str | int) -> Any:
    annotation = _unwrap_optional(annotation)
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        # a tagged union (the backend): pydantic's location names the member by its `type`
        for member in typing.get_args(annotation):
            literal = getattr(member, "model_fields", {}).get("type")
            if literal is not None and part in typing.get_args(literal.annotation):
                return member
        return None
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        if isinstance(part, str) and part in annotation.model_fields:
            return annotation.model_fields[part].annotation
        return annotation if part in BACKEND_TYPES else None
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is list and isinstance(part, int):
        return args[0]
    if origin is dict:
        return args[1]
    return None


def _unwrap_optional(annotation: Any) -> Any:
    """`X | None` and `Annotated[X, ...]` both mean X for key lookup."""
    while True:
        origin = typing.get_origin(annotation)
        if origin is typing.Annotated:
            annotation = typing.get_args(annotation)[0]
        elif origin in (typing.Union, types.UnionType):
            members = [a for a in typing.get_args(annotation) if a is not type(None)]
            if len(members) != 1:
                return annotation
            annotation = members[0]
        else:
            return annotation

