"""One error type for every user mistake in a YAML file.

Why: the CLI must print *one line per mistake* naming the file, the field path and what was
expected, and exit 2 without a traceback. Anything that is not a `SpecError` is a bug in
taskforge and is allowed to show its traceback.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from pydantic import ValidationError


@dataclass(frozen=True)
class SpecIssue:
    """One mistake: where it is (file + field path) and what was expected there."""

    file: str
    path: str
    message: str

    def __str__(self) -> str:
        where = f"{self.file}: {self.path}" if self.path else self.file
        return f"{where}: {self.message}"


class SpecError(Exception):
    """A user mistake in a task, agent or curriculum file (or a CLI argument naming one)."""

    def __init__(self, issues: Sequence[SpecIssue]):
        if not issues:
            raise ValueError("SpecError needs at least one issue")
        self.issues = list(issues)
        super().__init__("\n".join(str(i) for i in self.issues))

    @classmethod
    def single(cls, file: str | Path, path: str, message: str) -> SpecError:
        return cls([SpecIssue(str(file), path, message)])


def format_path(loc: Iterable[str | int]) -> str:
    """Render a location tuple as `stages[2].rewards[0].weight`."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """A ' (did you mean X?)' hint, or '' when nothing is close.

    Names here are built from parts (`object_to_goal_distance`), so candidates are ranked by the
    share of parts they have in common first, then by how alike the parts that differ are, then
    by the whole spelling: `handle_to_goal_distance` gets `object_to_goal_distance` (the parts
    `to_goal_distance` tie it with `tcp_to_goal_distance`; "handle" is more like "object" than
    "tcp"), where spelling alone picked the other."""
    choices = list(choices)
    if not choices:
        return ""
    mine = _parts(word)

    def score(choice: str) -> tuple[float, float, float]:
        theirs = _parts(choice)
        shared = len(set(mine) & set(theirs)) / max(len(mine), len(theirs))
        differing = difflib.SequenceMatcher(None, "_".join(p for p in mine if p not in theirs),
                                            "_".join(p for p in theirs if p not in mine)).ratio()
        return shared, differing, difflib.SequenceMatcher(None, word, choice).ratio()

    best = max(choices, key=score)
    shared, _, spelling = score(best)
    return f" (did you mean '{best}'?)" if shared >= 0.5 or spelling >= 0.6 else ""


def _parts(name: str) -> list[str]:
    return [p for p in re.split(r"[_\-.\s]+", name.lower()) if p]


def expected_one_of(word: str, choices: Iterable[str]) -> str:
    """`unknown X 'foo'; expected one of a, b, c (did you mean 'fo'?)`-style tail."""
    choices = sorted(choices)
    return f"expected one of {', '.join(choices)}{did_you_mean(word, choices)}"


def issues_from_validation(
    exc: ValidationError,
    file: str | Path,
    prefix: Sequence[str | int] = (),
    allowed_keys: Callable[[tuple[str | int, ...]], list[str]] | None = None,
    union_tags: Iterable[str] = (),
) -> list[SpecIssue]:
    """Translate pydantic's errors into one `SpecIssue` each.

    `allowed_keys(loc)` returns the field names valid at `loc` (pydantic's raw location), used to add a
    'did you mean' hint to unknown keys.
    """
    tags = set(union_tags)
    issues = []
    errors = _merge_misshapen(exc.errors(include_url=False))
    for err in errors:
        # pydantic puts the chosen member of a tagged union into `loc`; users never wrote it.
        raw = tuple(err["loc"])
        loc = [p for p in raw if not (isinstance(p, str) and p in tags)]
        kind = err["type"]
        ctx = err.get("ctx", {})
        if kind in ("union_tag_invalid", "union_tag_not_found"):
            loc.append(str(ctx.get("discriminator", "type")).strip("'"))
        path = format_path([*prefix, *loc])
        if kind == "misshapen":
            msg = (f"expected the field{'s' * (len(ctx['missing']) > 1)} {', '.join(map(repr, ctx['missing']))}, "
                   f"got {', '.join(map(repr, ctx['unknown']))}")
            fields = sorted(allowed_keys(raw)) if allowed_keys else []
            if set(fields) != set(ctx["missing"]):
                msg += f" (fields here: {', '.join(fields)})"
        elif kind == "extra_forbidden":
            key = str(loc[-1]) if loc else "?"
            names = allowed_keys(raw[:-1]) if allowed_keys else []
            msg = f"unknown field '{key}'; expected one of {', '.join(sorted(names))}{did_you_mean(key, names)}"
        elif kind == "missing":
            msg = "required field is missing"
        elif kind == "union_tag_not_found":
            msg = "required field is missing (it says which kind this is)"
        elif kind in ("union_tag_invalid", "literal_error"):
            given = str(ctx.get("tag", err.get("input", "")))
            raw_expected = str(ctx.get("expected_tags" if kind == "union_tag_invalid" else "expected", ""))
            expected = [t.strip(" '") for t in raw_expected.replace(" or ", ",").split(",") if t.strip(" '")]
            msg = f"unknown value '{given}'; {expected_one_of(given, expected)}"
        else:
            msg = err["msg"]
            if msg.startswith("Value error, "):
                msg = msg[len("Value error, ") :]
            if "input" in err and not isinstance(err["input"], (dict, list)):
                msg += f" (got {_short(err['input'])})"
        issues.append(SpecIssue(str(file), path, msg))
    return issues


def _merge_misshapen(errors: list[dict]) -> list[dict]:
    """A block written in another shape (`success: {feature: ..., below: ...}` for
    `success: {all: [...]}`) is one mistake: pydantic reports each missing field and each unknown
    key apart; they become one `misshapen` error at the block."""
    by_parent: dict[tuple, dict[str, list[str]]] = {}
    for err in errors:
        if err["type"] in ("missing", "extra_forbidden") and err["loc"]:
            kinds = by_parent.setdefault(tuple(err["loc"][:-1]), {"missing": [], "extra_forbidden": []})
            kinds[err["type"]].append(str(err["loc"][-1]))
    merged = {parent for parent, kinds in by_parent.items() if kinds["missing"] and kinds["extra_forbidden"]}
    out, done = [], set()
    for err in errors:
        parent = tuple(err["loc"][:-1]) if err["loc"] else None
        if parent in merged and err["type"] in ("missing", "extra_forbidden"):
            if parent not in done:
                done.add(parent)
                kinds = by_parent[parent]
                out.append({"type": "misshapen", "loc": parent, "msg": "",
                            "ctx": {"missing": kinds["missing"], "unknown": kinds["extra_forbidden"]}})
            continue
        out.append(err)
    return out


def _short(value: object, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
