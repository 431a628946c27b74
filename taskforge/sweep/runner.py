"""Running a sweep's trials as Ray tasks: on every core of this machine by default, across a Ray
cluster with `address`. Each trial is `taskforge train` on the variant's files with its seed,
then the trained policy meets every test condition; a trial that finished (final policy and
this evaluation on disk) is skipped, an unfinished one resumes from its checkpoint.

Why Ray tasks and not Ray Tune: a trial here is a whole training with its own checkpoints,
resume and evaluation, and nothing is searched or stopped early; Tune's trial scheduler,
searchers and its own checkpoint layer would add a second resume mechanism beside `train`'s.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from taskforge.agents.ray_shards import connect
from taskforge.evaluation import evaluate
from taskforge.run import RunDir, load_run, save_json
from taskforge.spec import SpecError
from taskforge.sweep.plan import Condition, SweepPlan, Trial, plan_sweep, write_plan
from taskforge.sweep.table import sweep_table, write_tables
from taskforge.training import train

Echo = Callable[[str], None]


class SweepInterrupted(Exception):
    """Ctrl-C or SIGTERM during a sweep: the running trials saved their checkpoints."""


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _evaluation_key(plan: SweepPlan) -> dict[str, Any]:
    """What a stored evaluation must match to be reused: the settings and the condition tasks."""
    return {"evaluation": plan.spec.evaluation.model_dump(mode="json"), "stage": plan.stage}


def finished(trial: Trial, plan: SweepPlan) -> dict[str, Any] | None:
    """The trial's stored results, if it was trained and evaluated as this plan asks. Only its
    `sweep_eval.json` is needed: a finished sweep kept without its policies (committed results)
    still counts as done."""
    run = RunDir(trial.run_dir)
    if not run.sweep_eval.is_file():
        return None
    stored = json.loads(run.sweep_eval.read_text())
    return stored if stored.get("key") == _evaluation_key(plan) else None


def _started(trial: Trial) -> bool:
    run = RunDir(trial.run_dir)
    return any(path.exists() for path in (run.checkpoint, run.final, run.sweep_eval))


def run_trial(trial: Trial, total_steps: int | None, conditions: list[Condition], stage: str,
              key: dict[str, Any]) -> dict[str, Any]:
    """Train (or resume, or skip if trained) one trial, then evaluate it under each condition;
    the results are also written to the run's `sweep_eval.json`. Runs inside a Ray task."""
    run = RunDir(trial.run_dir)
    started = time.perf_counter()
    if not run.final.is_file():  # with a final policy only the evaluation is (re)done
        train(trial.curriculum_file, run_dir=run.path, seed=trial.seed, steps=total_steps, resume=True, progress=False)
    loaded = load_run(run.path)
    ev = key["evaluation"]
    results = {
        c.name: evaluate(loaded.agent, c.task, c.task_file, stage, ev["split"], ev["episodes"], seed=ev["seed"]).as_dict()
        for c in conditions
    }
    record = {"key": key, "variant": trial.variant, "seed": trial.seed, "step": loaded.agent.global_step,
              "seconds": time.perf_counter() - started, "conditions": results}
    save_json(record, run.sweep_eval)
    return record


def run_sweep(sweep_file: str | Path, out: str | Path | None = None, address: str | None = None,
              resume: bool = False, echo: Echo = print) -> Path:
    """Run every trial of a sweep that has not finished, then write its tables and curves under
    the sweep's folder; returns the folder. Raises `SpecError` (before running anything) for a bad
    sweep file or a folder that already holds a sweep without `resume`."""
    plan = plan_sweep(sweep_file, out)
    started = [t for t in plan.trials if _started(t)]
    if started and not resume:
        raise SpecError.single(plan.out, "", f"already holds {len(started)} trial(s) of a sweep; pass --resume to "
                                              "continue it or choose another --out")
    write_plan(plan)
    key = _evaluation_key(plan)
    records = {(t.variant, t.seed): finished(t, plan) for t in plan.trials}
    todo = [t for t in plan.trials if records[(t.variant, t.seed)] is None]
    echo(f"sweep {plan.spec.name}: {len(plan.trials)} trials ({len(plan.trials) - len(todo)} already done), "
         f"results in {plan.out}")
    failures: list[str] = []
    if todo:
        ray = connect(address, log_to_driver=True)
        cpus = plan.spec.cpus_per_trial or os.cpu_count() or 1
        task = ray.remote(num_cpus=cpus, max_retries=0)(run_trial)
        pending = {task.remote(t, plan.spec.total_steps, plan.conditions, plan.stage, key): t for t in todo}
        previous_term = signal.signal(signal.SIGTERM, _interrupt)  # a job scheduler's stop: as Ctrl-C
        try:
            while pending:
                (ref,), _ = ray.wait(list(pending), num_returns=1)
                trial = pending.pop(ref)
                try:
                    record = ray.get(ref)
                except ray.exceptions.RayTaskError as error:
                    cause = error.cause if isinstance(error.cause, Exception) else error
                    failures.append(f"{trial.variant} seed {trial.seed}: {type(cause).__name__}: {cause}")
                    echo(f"failed: {failures[-1]}")
                    continue
                records[(trial.variant, trial.seed)] = record
                done = sum(r is not None for r in records.values())
                scores = ", ".join(f"{name} {r['success_rate']:.2f}" for name, r in record["conditions"].items())
                echo(f"[{done}/{len(plan.trials)}] {trial.variant}, seed {trial.seed}: {scores} "
                     f"({record['seconds'] / 60:.1f} min)")
                if pending:  # the table so far, so a long sweep's partial results are there to read
                    write_tables(plan, sweep_table(plan, _done(records), command=" ".join(sys.argv)))
        except KeyboardInterrupt:
            for ref in pending:
                ray.cancel(ref)  # a KeyboardInterrupt in the trial: train saves its checkpoint
            ray.wait(list(pending), num_returns=len(pending), timeout=60)
            raise SweepInterrupted(f"sweep interrupted; {len(pending)} trial(s) saved their checkpoints. "
                                   f"Continue with: taskforge sweep {sweep_file} --resume"
                                   + (f" --out {out}" if out else "")) from None
        finally:
            signal.signal(signal.SIGTERM, previous_term)
    for path in write_tables(plan, sweep_table(plan, _done(records), command=" ".join(sys.argv))):
        echo(f"wrote {path}")
    if failures:
        raise RuntimeError(f"{len(failures)} trial(s) failed:\n" + "\n".join(failures))
    return plan.out



def _done(records: dict[tuple[str, int], dict[str, Any] | None]) -> list[dict[str, Any]]:
    return [r for r in records.values() if r is not None]
