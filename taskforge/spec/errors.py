"""One error type for every user mistake in a YAML file.

Why: the CLI must print *one line per mistake* naming the file, the field path and what was
expected, and exit 2 without a traceback. Anything that is not a `SpecError` is a bug in
taskforge and is allowed to show its traceback.
"""

from __future__ import annotations

import difflib
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
    """A ' (did you mean X?)' hint, or '' when nothing is close."""
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


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
    for err in exc.errors(include_url=False):
        # pydantic puts the chosen member of a tagged union into `loc`; users never wrote it.
        raw = tuple(err["loc"])
        loc = [p for p in raw if not (isinstance(p, str) and p in tags)]
        kind = err["type"]
        ctx = err.get("ctx", {})
        if kind in ("union_tag_invalid", "union_tag_not_found"):
            loc.append(str(ctx.get("discriminator", "type")).strip("'"))
        path = format_path([*prefix, *loc])
        if kind == "extra_forbidden":
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


def _short(value: object, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
