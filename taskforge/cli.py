"""The `taskforge` command: argument parsing and error printing only.

Every user mistake arrives here as a `SpecError` and is printed one line per mistake
(`file: field.path: what was expected`) with exit code 2 and no traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from taskforge.spec import SpecError, SpecIssue, read_yaml

EXIT_USAGE = 2


def _kind_of(path: Path) -> str:
    """Task, agent or curriculum, from the top-level keys (falling back to the folder name)."""
    data = read_yaml(path)
    if "phases" in data:
        return "curriculum"
    if "stages" in data or "backend" in data:
        return "task"
    if {"ppo", "policy", "algo"} & data.keys():
        return "agent"
    for kind, folder in (("task", "tasks"), ("agent", "agents"), ("curriculum", "curricula")):
        if folder in path.parts:
            return kind
    raise SpecError.single(path, "", "cannot tell the kind of file; expected a task (stages), agent (ppo) or curriculum (phases)")


def cmd_validate(args: argparse.Namespace) -> int:
    from taskforge.envs import check_task_file, load_curriculum
    from taskforge.spec import load_agent_spec
    from taskforge.summary import agent_summary, curriculum_summary, task_summary

    issues: list[SpecIssue] = []
    for file in args.files:
        path = Path(file)
        try:
            kind = args.kind or _kind_of(path)
            if kind == "task":
                lines = task_summary(check_task_file(path))
            elif kind == "agent":
                lines = agent_summary(load_agent_spec(path))
            else:
                lines = curriculum_summary(load_curriculum(path))
        except SpecError as exc:
            issues += exc.issues
            continue
        print(f"{path}: ok")
        print("\n".join(lines))
    if issues:
        raise SpecError(issues)
    return 0


def cmd_tasks(args: argparse.Namespace) -> int:
    from taskforge.spec import load_task_spec

    root = Path(args.dir)
    if not root.is_dir():
        raise SpecError.single(root, "", "no such directory; expected the folder of task files (e.g. tasks/)")
    files = sorted(p for p in root.rglob("*.yaml") if "stages" in read_yaml(p))
    for path in files:
        task = load_task_spec(path)
        source = getattr(task.backend, "task_set", None) or task.backend.env
        print(f"{path}  [{task.backend.type}: {source}]  {' -> '.join(task.stage_names)}")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from taskforge.envs import load_curriculum
    from taskforge.summary import curriculum_summary

    curriculum = load_curriculum(args.curriculum)
    print("\n".join(curriculum_summary(curriculum)))
    print("training is not implemented yet (see the training issue); the curriculum above is valid.")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="taskforge", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("validate", help="check task / agent / curriculum files and summarise them")
    p.add_argument("files", nargs="+")
    p.add_argument("--kind", choices=["task", "agent", "curriculum"], help="default: guessed from the file")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser("tasks", help="list task files and their stages")
    p.add_argument("--dir", default="tasks", help="folder to search (default: tasks)")
    p.set_defaults(func=cmd_tasks)

    p = sub.add_parser("train", help="train an agent along a curriculum")
    p.add_argument("curriculum")
    p.set_defaults(func=cmd_train)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except SpecError as exc:
        for issue in exc.issues:
            print(f"error: {issue}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
