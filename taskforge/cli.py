"""The `taskforge` command: argument parsing and error printing only.

Every user mistake arrives here as a `SpecError` and is printed one line per mistake
(`file: field.path: what was expected`) with exit code 2 and no traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from taskforge.spec import SpecError, SpecIssue, expected_one_of, read_yaml_with_base

EXIT_USAGE = 2


def _kind_of(path: Path) -> str:
    """Task, agent, curriculum or sweep, from the top-level keys (a variant's merged with its base's;
    falling back to the folder name)."""
    data = read_yaml_with_base(path)
    if "variants" in data:
        return "sweep"
    if "phases" in data:
        return "curriculum"
    if {"stages", "backend"} & data.keys():
        return "task"
    if {"ppo", "policy", "algo", "rl2"} & data.keys():
        return "agent"
    for kind, folder in (("task", "tasks"), ("agent", "agents"), ("curriculum", "curricula"), ("sweep", "sweeps")):
        if folder in path.parts:
            return kind
    raise SpecError.single(path, "", "cannot tell the kind of file; expected a task (stages), agent (ppo), curriculum (phases) or sweep (variants)")


def cmd_validate(args: argparse.Namespace) -> int:
    from taskforge.envs import check_task_file, load_curriculum, probe_phases
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
            elif kind == "sweep":
                from taskforge.sweep import plan_sweep

                plan = plan_sweep(path)
                lines = [f"  {len(plan.spec.variants)} variants x {len(plan.spec.seeds)} seeds = {len(plan.trials)} trials; "
                         f"tested under: {', '.join(c.name for c in plan.conditions)} (stage {plan.stage})"]
            else:
                curriculum = load_curriculum(path)
                # One policy for every phase: their observation/action shapes must agree.
                shapes = probe_phases([(p.task, p.task_file) for p in curriculum.phases], curriculum.agent.asymmetric_critic, path)
                ws = curriculum.spec.warm_start
                if ws is not None and ws.demos is not None:  # the demos file, as `train` will read it
                    from taskforge.agents import agent_observation_space
                    from taskforge.training.warm_start import load_demos_file

                    space = agent_observation_space(curriculum.agent, shapes.observation_space, shapes.action_space)
                    load_demos_file(curriculum, space.shape[0])
                if curriculum.init_from is not None:  # the weights, as `train` will load them
                    from taskforge.run import build_agent
                    from taskforge.training import load_init_from

                    agent, _ = build_agent(curriculum.agent, [(p.task, p.task_file) for p in curriculum.phases],
                                           curriculum.spec.seed, path, curriculum.agent_file)
                    load_init_from(curriculum, agent, curriculum.spec.seed)
                lines = curriculum_summary(curriculum)
                for warning in curriculum.warnings:
                    print(f"warning: {warning}", file=sys.stderr)
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
    broken: list[SpecIssue] = []
    for path in sorted(root.rglob("*.yaml")):
        try:  # one broken file is one line; the others are still listed
            if "stages" not in read_yaml_with_base(path):
                continue
            task = load_task_spec(path)
        except SpecError as exc:
            broken += exc.issues[:1]
            print(f"{path}  [broken: {len(exc.issues)} mistake{'s' * (len(exc.issues) > 1)}, see below]")
            continue
        print(f"{path}  [{task.backend.type}: {task.backend.describe()}]  {' -> '.join(task.stage_names)}")
    if broken:
        raise SpecError(broken)  # the first mistake of each broken file (`validate FILE` lists all)
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    import json

    from taskforge.run import RunDir, load_checkpoint
    from taskforge.training import Interrupted, train

    if args.steps is not None and args.steps < 1:
        raise SpecError.single("--steps", "", f"expected a positive number of steps (got {args.steps})")
    if args.stop_at is not None and args.stop_at < 1:
        raise SpecError.single("--stop-at", "", f"expected a positive step count (got {args.stop_at})")
    try:
        run_dir = train(args.curriculum, run_dir=args.run_dir, seed=args.seed, steps=args.steps,
                        resume=args.resume, progress=not args.no_progress, stop_at=args.stop_at)
    except Interrupted as exc:
        print(str(exc), file=sys.stderr)
        return 130
    run = RunDir(run_dir)
    state = load_checkpoint(run.checkpoint)
    step, total = state["agent"]["global_step"], state["config"]["total_steps"]
    if step >= total:
        print(f"done: {run} (final policy {run.final})")
        if run.final_eval.is_file():
            ev = json.loads(run.final_eval.read_text())
            low, high = ev["success_ci95"]
            tasks = ev.get("tasks", [])
            over = f", {len(tasks)} tasks" if tasks else ""
            print(f"held-out success of '{ev['stage']}' ({ev['split']} split, {ev['episodes']} episodes{over}): "
                  f"{ev['success_rate']:.2f} (95 % CI {low:.2f}-{high:.2f})")
            for row in tasks:
                print(f"  {row['task']}: {row['success_rate']:.2f} ({row['successes']}/{row['episodes']})")
    else:
        print(f"paused at step {step:,} of {total:,}: {run} (continue with --resume)")
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from taskforge.sweep import SweepInterrupted, plan_sweep, run_sweep

    if args.dry_run:
        plan = plan_sweep(args.sweep, args.out)
        for trial in plan.trials:
            print(f"{trial.variant}, seed {trial.seed}: {trial.run_dir}")
        print(f"{len(plan.trials)} trials; tested under: {', '.join(c.name for c in plan.conditions)}")
        return 0
    try:
        out = run_sweep(args.sweep, out=args.out, address=args.address, resume=args.resume)
    except SweepInterrupted as exc:
        print(str(exc), file=sys.stderr)
        return 130
    except RuntimeError as exc:  # trials failed; the others' results are written
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print((out / "table.md").read_text())
    return 0


def cmd_demos(args: argparse.Namespace) -> int:
    from taskforge.demos import generate, save
    from taskforge.envs import load_task

    if args.episodes < 1:
        raise SpecError.single("--episodes", "", f"expected at least 1 episode (got {args.episodes})")
    task = load_task(args.task)
    stage = args.stage or task.stages[-1].name
    if stage not in task.stage_names:
        raise SpecError.single(args.task, "stage", f"no stage '{stage}'; {expected_one_of(stage, task.stage_names)}")
    out = Path(args.out or f"demos/{task.name}-{stage}.npz")
    if out.exists() and not args.force:
        raise SpecError.single(out, "", "already exists; pass --force to overwrite it or choose another --out")
    demos = generate(args.task, stage, args.episodes, seed=args.seed, split=args.split,
                     keep_failed=args.keep_failed, source=args.policy, progress=not args.no_progress)
    meta = demos.metadata
    print(f"{task.name}:{stage} ({meta['policy']}, {args.split} goals): {meta['successes']}/{args.episodes} "
          f"episodes succeeded (success rate {meta['success_rate']:.2f})")
    if demos.num_steps == 0:
        print("error: no successful episode; nothing written (--keep-failed keeps failed ones)", file=sys.stderr)
        return 1
    save(demos, out)
    print(f"wrote {out}: {demos.num_episodes} episodes, {demos.num_steps} steps")
    return 0


def cmd_eval(args: argparse.Namespace) -> int:
    from taskforge.evaluation.report import evaluate_run, format_table
    from taskforge.run import save_json

    if args.episodes < 1:
        raise SpecError.single("--episodes", "", f"expected at least 1 trial (got {args.episodes})")
    if args.trial_episodes is not None and args.trial_episodes < 1:
        raise SpecError.single("--trial-episodes", "", f"expected at least 1 episode per trial (got {args.trial_episodes})")
    report = evaluate_run(args.run, split=args.split, trials=args.episodes, stages=args.stage, seed=args.seed,
                          trial_episodes=args.trial_episodes, deterministic=not args.stochastic,
                          stop_on_success=args.stop_on_success)
    print(format_table(report))
    if args.out:
        save_json(report, Path(args.out))
        print(f"wrote {args.out}")
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from taskforge.evaluation.plot import plot_adaptation, plot_run

    reports = [Path(s) for s in args.sources if s.endswith(".json")]
    if reports and len(reports) < len(args.sources):
        raise SpecError.single(args.sources[0], "", "expected either one run directory or only eval reports (.json)")
    if not reports and len(args.sources) > 1:
        raise SpecError.single(args.sources[1], "", "expected one run directory (several sources must be eval reports)")
    print(f"wrote {plot_adaptation(reports, args.out) if reports else plot_run(args.sources[0], args.out)}")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from taskforge.rendering import policy_actor, render_episodes, scripted_actor

    target = Path(args.target)
    actor = (scripted_actor(target, args.stage, args.split) if target.suffix in (".yaml", ".yml")
             else policy_actor(target, args.stage, args.split))
    frames, successes = render_episodes(actor.env, actor.act, Path(args.out), episodes=args.episodes, seed=args.seed,
                                        camera=args.camera, width=args.width, height=args.height, max_frames=args.max_frames)
    print(f"wrote {args.out}: {frames} frames, {actor.source}, stage {actor.env.unwrapped.stage}, "
          f"success {sum(successes)}/{len(successes)}")
    return 0


def cmd_inspect(args: argparse.Namespace) -> int:
    import textwrap

    from taskforge.envs import TaskEnv, load_task
    from taskforge.inspection import model_names, scripted_trace

    task = load_task(args.task)
    stage = args.stage or task.stages[-1].name
    if stage not in task.stage_names:
        raise SpecError.single(args.task, "stage", f"no stage '{stage}'; {expected_one_of(stage, task.stage_names)}")
    if args.every < 1:
        raise SpecError.single("--every", "", f"expected a positive number of steps (got {args.every})")
    env = TaskEnv(task, args.task, stage=stage, split=args.split, task_name=args.sub_task)
    names = model_names(env, args.sub_task)
    print(f"{args.task}: {task.backend.describe()}" + ("" if names else " (no MuJoCo model: no element names)"))
    for kind, found in names.items():
        print(textwrap.fill(", ".join(found) or "-", width=110, initial_indent=f"  {kind} ({len(found)}): ",
                            subsequent_indent="      "))
    trace = scripted_trace(env, stage, seed=args.seed, goal_index=args.goal)
    first = trace.first_success
    print(f"\nstage {stage}, {args.split} goal {args.goal}, scripted policy {trace.policy}: "
          f"{'never succeeds' if first is None else f'succeeds at step {first}'}")
    print(trace.table(args.every))
    if args.csv:
        trace.write_csv(Path(args.csv))
        print(f"wrote {args.csv}: every step of the episode")
    env.close()
    return 0


def cmd_schema(args: argparse.Namespace) -> int:
    import json

    from taskforge.atomic import atomic_write
    from taskforge.spec.schema import json_schema

    text = json.dumps(json_schema(args.kind), indent=2) + "\n"
    if args.out:
        atomic_write(Path(args.out), lambda f: f.write(text.encode()))
        print(f"wrote {args.out}")
    else:
        print(text, end="")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="taskforge", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("validate", help="check task / agent / curriculum / sweep files and summarise them")
    p.add_argument("files", nargs="+")
    p.add_argument("--kind", choices=["task", "agent", "curriculum", "sweep"], help="default: guessed from the file")
    p.set_defaults(func=cmd_validate)

    p = sub.add_parser("tasks", help="list task files and their stages")
    p.add_argument("--dir", default="tasks", help="folder to search (default: tasks)")
    p.set_defaults(func=cmd_tasks)

    p = sub.add_parser("train", help="train an agent along a curriculum")
    p.add_argument("curriculum")
    p.add_argument("--run-dir", help="default: runs/<curriculum name>-seed<seed>")
    p.add_argument("--seed", type=int, help="default: the curriculum's seed")
    p.add_argument("--steps", type=int, help="total env steps (default: the curriculum's total_steps)")
    p.add_argument("--resume", action="store_true", help="continue from the run directory's last checkpoint")
    p.add_argument("--stop-at", type=int, metavar="STEP",
                   help="pause at this env step with a checkpoint (e.g. a job's time limit); the learning-rate "
                        "schedule still spans --steps; continue later with --resume")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (e.g. in logs)")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("sweep", help="train every variant x seed of a sweep file (Ray) and table them under its test conditions")
    p.add_argument("sweep", metavar="SWEEP.yaml")
    p.add_argument("--address", help="a Ray cluster to run on (default: RAY_ADDRESS, else a local Ray instance on this machine)")
    p.add_argument("--out", help="the sweep's folder (default: runs/sweeps/<sweep name>)")
    p.add_argument("--resume", action="store_true", help="skip finished trials, resume unfinished ones from their checkpoints")
    p.add_argument("--dry-run", action="store_true", help="check the sweep file and list its trials; train nothing")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("demos", help="record scripted demonstrations of a task's stage")
    p.add_argument("task", metavar="TASK.yaml")
    p.add_argument("--stage", help="default: the task's last stage")
    p.add_argument("--episodes", type=int, default=20, help="episodes to run (default 20); failed ones are dropped")
    p.add_argument("--out", help="default: demos/<task name>-<stage>.npz")
    p.add_argument("--seed", type=int, default=0, help="episode k resets with seed + k on goal (seed + k) mod goals")
    p.add_argument("--split", choices=["train", "test"], default="train")
    p.add_argument("--keep-failed", action="store_true", help="keep failed episodes too")
    p.add_argument("--policy", choices=["auto", "native", "planner"], default="auto",
                   help="the simulator's own scripted policy, the waypoint planner, or auto (native on the last stage)")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_demos)

    p = sub.add_parser("eval", help="evaluate a trained policy on held-out goals")
    p.add_argument("run", metavar="RUN_DIR_OR_CHECKPOINT")
    p.add_argument("--split", choices=["train", "test"], default="test")
    p.add_argument("--episodes", type=int, default=20,
                   help="trials per task and stage, trial k on goal k of the split (default 20); a trial is "
                        "--trial-episodes episodes from a fresh recurrent state")
    p.add_argument("--trial-episodes", type=int,
                   help="episodes per trial (default: the agent's: K for RL², 1 for PPO; K > 1 for PPO gives the "
                        "memoryless baseline's flat adaptation curve)")
    p.add_argument("--stage", action="append", help="only these stages (repeatable)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--stochastic", action="store_true",
                   help="sample actions from the policy (seeded by --seed) instead of taking its mean; an RL² "
                        "policy explores by sampling, as in Duan et al.'s meta-test")
    p.add_argument("--stop-on-success", action="store_true",
                   help="end each episode at its first success (the same success rate in fewer steps; what a "
                        "curriculum's evaluation.stop_on_success does in training)")
    p.add_argument("--out", help="write the report as JSON here")
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("render", help="record episodes off-screen (scripted for a task file, the policy for a run)")
    p.add_argument("target", metavar="TASK.yaml|RUN_DIR")
    p.add_argument("--out", default="render.gif", help="a .gif or .mp4 file (default render.gif)")
    p.add_argument("--stage", help="default: the task's first stage (task file) or the run's last stage")
    p.add_argument("--split", choices=["train", "test"], default="test")
    p.add_argument("--episodes", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--camera", help="a camera of the model (default: corner for Meta-World, front for xArm7)")
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--max-frames", type=int, help="stop after this many frames")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("plot", help="learning curves of a run, or adaptation curves of eval reports, as a PNG")
    p.add_argument("sources", nargs="+", metavar="RUN_DIR|REPORT.json",
                   help="a run directory (learning curves), or one or more `taskforge eval --out` reports "
                        "(success per episode of the trial, e.g. RL² next to PPO)")
    p.add_argument("--out", help="default: RUN_DIR/curves.png, or adaptation.png beside the first report")
    p.set_defaults(func=cmd_plot)

    p = sub.add_parser("inspect", help="a task's model names by kind, and a scripted episode's features and rewards per step")
    p.add_argument("task", metavar="TASK.yaml")
    p.add_argument("--stage", help="default: the task's last stage")
    p.add_argument("--split", choices=["train", "test"], default="train")
    p.add_argument("--goal", type=int, default=0, help="goal index of the split (default 0)")
    p.add_argument("--sub-task", help="for a task set (MT10): which sub-task (default the first)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--every", type=int, default=10, help="print every N-th step (default 10); --csv has them all")
    p.add_argument("--csv", help="write every step as CSV here")
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser("schema", help="JSON Schema of task, agent, curriculum or sweep files, for editors")
    p.add_argument("kind", choices=["task", "agent", "curriculum", "sweep"])
    p.add_argument("--out", help="write it here instead of printing it")
    p.set_defaults(func=cmd_schema)
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
