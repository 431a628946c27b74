"""The training loop end to end on tiny budgets: curriculum promotion, checkpoints, interrupt
and resume, evaluation reports, plots, and bad CLI input."""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from gymnasium.spaces import Box

from taskforge.agents import PPOAgent
from taskforge.cli import main
from taskforge.envs import TaskEnv, load_task
from taskforge.evaluation.report import format_table
from taskforge.rollouts import evaluate, evaluate_rows
from taskforge.run import load_checkpoint, read_jsonl, save_checkpoint
from taskforge.training import train
from tests.conftest import ROOT, TASKS
from tests.test_agents_ppo import SMALL_PPO, agent_spec

# Pendulum is a fast stand-in simulator; the curriculum logic is the same for every backend.
TASK = {
    "name": "pendulum-two-stage",
    "backend": {"type": "gymnasium", "env": "Pendulum-v1"},
    "max_episode_steps": 100,
    "goals": {"train": {"count": 1000}, "test": {"count": 10}},
    "stages": [
        # always succeeds: promotion as soon as the window is full and min_steps passed
        {"name": "easy", "rewards": [{"term": "native"}], "success": {"all": [{"feature": "native_return", "above": -1e9}]}},
        {"name": "hard", "rewards": [{"term": "native"}], "success": {"all": [{"feature": "native_return", "above": 1e9}]}},
    ],
}
AGENT = {
    "name": "tiny",
    "policy": {"hidden_sizes": [32, 32]},
    "ppo": {"num_envs": 2, "rollout_steps": 100, "num_minibatches": 2, "update_epochs": 2},
    "runtime": {"vector": "sync"},
}


def write_curriculum(folder: Path, **overrides) -> Path:
    (folder / "task.yaml").write_text(yaml.safe_dump(TASK))
    (folder / "agent.yaml").write_text(yaml.safe_dump(AGENT))
    doc = {
        "name": "tiny",
        "agent": "agent.yaml",
        "seed": 3,
        "total_steps": 1200,
        "phases": [{"task": "task.yaml"}],
        "promotion": {"threshold": 0.9, "window": 4, "min_steps": 300},
        "replay": {"fraction": 0.0},
        "evaluation": {"every_steps": 600, "episodes": 2},
        "checkpoint": {"every_steps": 200},
    }
    doc.update(overrides)
    path = folder / "curriculum.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_train_promotes_logs_checkpoints_and_writes_final_policy(tmp_path):
    run = train(write_curriculum(tmp_path), run_dir=tmp_path / "run", progress=False)
    events = read_jsonl(run / "events.jsonl")
    assert [(e["kind"], e["from_stage"], e["to_stage"]) for e in events] == [("promote", "easy", "hard")]
    assert events[0]["step"] >= 300  # min_steps
    metrics = read_jsonl(run / "metrics.jsonl")
    assert [m["step"] for m in metrics] == list(range(200, 1201, 200))
    assert metrics[0]["stage"] == "easy" and metrics[-1]["stage"] == "hard"
    for key in ("return_mean", "steps_per_s", "policy_loss", "value_loss", "entropy", "approx_kl", "learning_rate"):
        assert key in metrics[-1], key
    assert "eval_success_rate" in metrics[2]  # step 600
    assert any((run / "tensorboard").iterdir())
    assert json.loads((run / "config.json").read_text())["seed"] == 3
    ckpt = load_checkpoint(run / "checkpoint.pt")
    assert ckpt["agent"]["global_step"] == 1200
    assert ckpt["curriculum"] and (run / "final.pt").is_file()


def test_same_seed_same_run(tmp_path):
    cur = write_curriculum(tmp_path, total_steps=400)
    a = load_checkpoint(train(cur, run_dir=tmp_path / "a", progress=False) / "final.pt")
    b = load_checkpoint(train(cur, run_dir=tmp_path / "b", progress=False) / "final.pt")
    for key, value in a["agent"]["policy"].items():
        assert torch.equal(value, b["agent"]["policy"][key]), key


def test_resume_continues_step_count_and_curriculum_state(tmp_path):
    cur = write_curriculum(tmp_path)
    run = tmp_path / "run"
    train(cur, run_dir=run, steps=600, progress=False)
    first = load_checkpoint(run / "checkpoint.pt")
    assert first["agent"]["global_step"] == 600
    train(cur, run_dir=run, steps=1200, resume=True, progress=False)
    second = load_checkpoint(run / "checkpoint.pt")
    assert second["agent"]["global_step"] == 1200
    steps = [m["step"] for m in read_jsonl(run / "metrics.jsonl")]
    assert steps == sorted(set(steps)) and steps[-1] == 1200  # no duplicates across the resume
    # the curriculum picked up where it left off: one promotion in the whole run
    assert len(read_jsonl(run / "events.jsonl")) == 1
    assert second["curriculum"]["events"][:len(first["curriculum"]["events"])] == first["curriculum"]["events"]


def test_stop_at_pauses_without_bending_the_learning_rate_schedule(tmp_path, capsys):
    cur = write_curriculum(tmp_path, total_steps=1200)
    whole = train(cur, run_dir=tmp_path / "whole", progress=False)
    run = tmp_path / "chunked"
    assert main(["train", str(cur), "--run-dir", str(run), "--stop-at", "600", "--no-progress"]) == 0
    assert "paused at step 600 of 1,200" in capsys.readouterr().out
    assert load_checkpoint(run / "checkpoint.pt")["agent"]["global_step"] == 600
    assert not (run / "final.pt").exists()  # a paused run has no final policy yet
    assert main(["train", str(cur), "--run-dir", str(run), "--resume", "--no-progress"]) == 0
    assert (run / "final.pt").is_file()
    # the schedule spans the whole run in both: annealing is not restarted per chunk
    def lr(d):
        return [(m["step"], m["learning_rate"]) for m in read_jsonl(d / "metrics.jsonl")]
    assert lr(run) == lr(whole)
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "bad"), "--stop-at", "0"]) == 2
    assert "--stop-at" in capsys.readouterr().err and not (tmp_path / "bad").exists()


def test_ctrl_c_saves_a_checkpoint_that_resumes(tmp_path):
    cur = write_curriculum(tmp_path, total_steps=100_000, checkpoint={"every_steps": 100_000})
    run = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "taskforge.cli", "train", str(cur), "--run-dir", str(run), "--no-progress"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        # a shell starts background jobs (`make test &`) with SIGINT ignored, and Python then
        # installs no Ctrl-C handler in the child: give it the terminal's default disposition
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.time() + 60
    while time.time() < deadline and len(read_jsonl(run / "metrics.jsonl")) < 3:
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=180)  # generous: a loaded machine (another training) slows the save
    assert proc.returncode == 130, err
    assert "interrupted at step" in err and "Traceback" not in err
    saved = load_checkpoint(run / "checkpoint.pt")
    step = saved["agent"]["global_step"]
    assert step >= 400  # at least the update before the last logged one was complete
    with open(run / "checkpoint.pt", "rb") as f:
        before = hashlib.sha256(f.read()).hexdigest()
    # a second plain `train` into the same dir refuses and leaves the checkpoint untouched
    assert main(["train", str(cur), "--run-dir", str(run), "--no-progress"]) == 2
    with open(run / "checkpoint.pt", "rb") as f:
        assert hashlib.sha256(f.read()).hexdigest() == before
    train(cur, run_dir=run, steps=step + 200, resume=True, progress=False)
    assert load_checkpoint(run / "checkpoint.pt")["agent"]["global_step"] == step + 200


def test_ctrl_c_during_the_first_rollout_after_a_resume_says_what_is_discarded(tmp_path):
    """The state after the last complete update is what a Ctrl-C keeps; a rollout in progress is
    named as discarded rather than dropped silently (a resumed run seemed to stand still)."""
    import yaml

    cur = write_curriculum(tmp_path, total_steps=400_000)
    agent = {**AGENT, "ppo": {**AGENT["ppo"], "rollout_steps": 20_000}}  # 40,000 steps per update
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(agent))
    run = tmp_path / "run"
    train(cur, run_dir=run, stop_at=40_000, progress=False)
    proc = subprocess.Popen(
        [sys.executable, "-m", "taskforge", "train", str(cur), "--run-dir", str(run), "--resume"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    for line in proc.stderr:  # the start-up lines come before the first rollout
        if "starting 2 envs" in line:
            break
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert re.search(r"interrupted at step 40,000 \(the [\d,]+ steps collected since were not yet learnt from and are discarded\)", err), err
    assert load_checkpoint(run / "checkpoint.pt")["agent"]["global_step"] == 40_000


def test_kill_at_any_moment_leaves_a_loadable_checkpoint(tmp_path):
    cur = write_curriculum(tmp_path, total_steps=100_000, checkpoint={"every_steps": 200})
    run = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "taskforge.cli", "train", str(cur), "--run-dir", str(run), "--no-progress"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    deadline = time.time() + 60
    while time.time() < deadline and not (run / "checkpoint.pt").exists():
        time.sleep(0.05)
    time.sleep(1.0)
    os.kill(proc.pid, signal.SIGKILL)  # no chance to clean up
    proc.wait()
    state = load_checkpoint(run / "checkpoint.pt")
    assert state["agent"]["global_step"] % 200 == 0
    # resuming sweeps away a half-written temp file the kill may have left
    train(cur, run_dir=run, steps=state["agent"]["global_step"] + 200, resume=True, progress=False)
    assert not list(run.glob(".*.tmp"))


def test_eval_writes_a_well_formed_report(tmp_path, capsys):
    run = train(write_curriculum(tmp_path, total_steps=400), run_dir=tmp_path / "run", progress=False)
    out = tmp_path / "report.json"
    assert main(["eval", str(run), "--episodes", "3", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "95% CI" in table and "easy" in table and "hard" in table
    report = json.loads(out.read_text())
    assert report["split"] == "test" and report["step"] == 400
    assert [r["stage"] for r in report["rows"]] == ["easy", "hard"]
    for row in report["rows"]:
        assert row["episodes"] == 3
        low, high = row["success_ci95"]
        assert 0.0 <= low <= row["success_rate"] <= high <= 1.0
        assert row["mean_length"] == 100
    assert report["rows"][0]["success_rate"] == 1.0 and report["rows"][1]["success_rate"] == 0.0

    # ending episodes at their first success: the same successes, the easy stage's episodes shorter
    assert main(["eval", str(run), "--episodes", "3", "--stop-on-success", "--out", str(out)]) == 0
    stopped = json.loads(out.read_text())
    assert stopped["stop_on_success"] and not report["stop_on_success"]
    assert [(r["successes"], r["episodes"]) for r in stopped["rows"]] == [(3, 3), (0, 3)]
    easy, hard = stopped["rows"]
    assert easy["mean_length"] < 100 and hard["mean_length"] == 100, (easy, hard)


def test_stochastic_eval_is_seeded_and_leaves_the_agents_random_stream_alone(tmp_path, capsys):
    """`--stochastic` samples actions: the same seed gives the same report, another seed or the
    mean action a different one; evaluating never moves the agent's own generator (the trainer
    evaluates mid-run)."""
    from taskforge.rollouts import evaluate
    from taskforge.run import load_run

    run = train(write_curriculum(tmp_path, total_steps=400), run_dir=tmp_path / "run", progress=False)

    def returns(*args: str) -> list[str | float]:  # [action mode, mean return]
        out = tmp_path / "report.json"
        assert main(["eval", str(run), "--episodes", "2", "--stage", "easy", "--out", str(out), *args]) == 0
        report = json.loads(out.read_text())
        return [report["actions"], report["rows"][0]["mean_return"]]

    sampled = returns("--stochastic", "--seed", "1")
    assert sampled[0] == "sampled" and "sampled actions" in capsys.readouterr().out
    assert returns("--stochastic", "--seed", "1") == sampled
    assert returns("--stochastic", "--seed", "2")[1] != sampled[1]
    mean = returns("--seed", "1")
    assert mean[0] == "mean" and mean[1] != sampled[1]

    loaded = load_run(run / "final.pt")
    agent = loaded.agent
    task, task_file, _ = loaded.phases[0]
    before = agent.generator.get_state()
    evaluate(agent, task, task_file, "easy", "test", 1, seed=5, deterministic=False)
    assert torch.equal(agent.generator.get_state(), before)


def test_plot_writes_a_png_whose_legend_says_what_each_curve_measures(tmp_path):
    """The training curve follows the stage being trained (easy, then hard), the evaluation one
    fixed stage on the test goals: a reader must not take one for the other."""
    from taskforge.evaluation.plot import run_figure

    cur = write_curriculum(tmp_path, total_steps=1200, evaluation={"every_steps": 600, "episodes": 2, "stage": "hard"})
    run = train(cur, run_dir=tmp_path / "run", progress=False)
    assert main(["plot", str(run)]) == 0
    assert (run / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    legend = [t.get_text() for t in run_figure(run).axes[1].get_legend().get_texts()]
    assert legend == ["training episodes, train goals: the stage being trained (easy → hard)",
                      "evaluation, test goals: stage hard"]


def test_plot_of_one_episode_trials_draws_bars_not_a_degenerate_curve(tmp_path):
    from taskforge.evaluation.plot import adaptation_figure

    run = train(write_curriculum(tmp_path, total_steps=400), run_dir=tmp_path / "run", progress=False)
    assert main(["eval", str(run), "--episodes", "2", "--out", str(tmp_path / "ppo.json")]) == 0
    fig = adaptation_figure([tmp_path / "ppo.json"])
    ax = fig.axes[0]
    assert len(ax.patches) == 2 and "no adaptation curve" in ax.get_title()  # one bar per stage
    assert main(["plot", str(tmp_path / "ppo.json")]) == 0 and (tmp_path / "adaptation.png").is_file()


@pytest.mark.parametrize(
    "args,fragment",
    [
        (["train", "missing.yaml"], "missing.yaml: no such file"),
        (["train", "{bad}"], "no such file"),
        (["eval", "nowhere"], "nowhere: no such run directory or checkpoint file"),
        (["plot", "."], "no metrics.jsonl"),
    ],
)
def test_bad_cli_input_is_one_line_and_exit_2(args, fragment, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and fragment in err[0], err


def test_init_from_starts_with_another_runs_weights_and_statistics_but_a_fresh_count(tmp_path):
    source = train(write_curriculum(tmp_path, total_steps=400), run_dir=tmp_path / "source", progress=False)
    learnt = load_checkpoint(source / "final.pt")["agent"]
    # the same task and networks with a learning rate too small to move a weight: whatever the
    # new run ends with, it started from
    (tmp_path / "still.yaml").write_text(yaml.safe_dump({**AGENT, "ppo": {**AGENT["ppo"], "learning_rate": 1e-12}}))
    cur = write_curriculum(tmp_path, total_steps=200, agent="still.yaml", init_from="source")
    run = train(cur, run_dir=tmp_path / "continued", progress=False)
    state = load_checkpoint(run / "final.pt")["agent"]
    for key, value in learnt["policy"].items():
        torch.testing.assert_close(state["policy"][key], value, atol=1e-6, rtol=0, msg=key)
    records = read_jsonl(run / "metrics.jsonl")
    assert state["global_step"] == 200 and [m["step"] for m in records] == [0, 200]
    assert "eval_success_rate" in records[0]  # evaluated before the first update: the curve starts at the loaded weights
    # the statistics carried on: the source's samples plus this run's
    assert int(state["obs_normalizer"]["count"]) > int(learnt["obs_normalizer"]["count"]) > 0
    # and the same run without init_from ends elsewhere: the check above is not of a fixed point
    fresh = train(write_curriculum(tmp_path, total_steps=200, agent="still.yaml"), run_dir=tmp_path / "fresh", progress=False)
    first = next(iter(learnt["policy"]))
    assert not torch.allclose(load_checkpoint(fresh / "final.pt")["agent"]["policy"][first], learnt["policy"][first], atol=1e-3)


def test_init_from_with_a_seed_placeholder_starts_each_seed_from_its_own_source(tmp_path, capsys):
    for seed in (3, 4):
        train(write_curriculum(tmp_path, total_steps=200), run_dir=tmp_path / f"source-seed{seed}", seed=seed, progress=False)
    (tmp_path / "still.yaml").write_text(yaml.safe_dump({**AGENT, "ppo": {**AGENT["ppo"], "learning_rate": 1e-12}}))
    cur = write_curriculum(tmp_path, total_steps=200, agent="still.yaml", init_from="source-seed{seed}")
    assert main(["validate", str(cur)]) == 0  # checked at the curriculum's own seed, 3
    assert "source-seed{seed} ({seed}: the run's seed)" in capsys.readouterr().out
    run = train(cur, run_dir=tmp_path / "continued", seed=4, progress=False)
    state = load_checkpoint(run / "final.pt")["agent"]["policy"]
    own, other = (load_checkpoint(tmp_path / f"source-seed{s}" / "final.pt")["agent"]["policy"] for s in (4, 3))
    first = next(iter(own))
    torch.testing.assert_close(state[first], own[first], atol=1e-6, rtol=0)
    assert not torch.allclose(state[first], other[first], atol=1e-3)
    # a seed whose source does not exist: one line naming it, nothing written
    capsys.readouterr()  # the run's progress lines
    assert main(["train", str(cur), "--seed", "5", "--run-dir", str(tmp_path / "run5"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {cur}: init_from: ") and str(tmp_path / "source-seed5") in err[0], err
    assert not (tmp_path / "run5").exists()
    # any other placeholder is a schema error
    bad = write_curriculum(tmp_path, init_from="source-{run}")
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "init_from" in err[0] and "the only placeholder init_from may hold is {seed}" in err[0], err


@pytest.mark.parametrize("case", ["other-network", "missing", "with-warm-start"])
def test_init_from_that_cannot_be_used_is_one_line_and_writes_nothing(case, tmp_path, capsys):
    if case != "missing":
        train(write_curriculum(tmp_path, total_steps=200), run_dir=tmp_path / "source", progress=False)
    overrides: dict = {"init_from": "source"}
    if case == "other-network":
        (tmp_path / "wide.yaml").write_text(yaml.safe_dump({**AGENT, "policy": {"hidden_sizes": [48, 32]}}))
        overrides["agent"] = "wide.yaml"
    if case == "with-warm-start":
        overrides["warm_start"] = {"generate_episodes": 2}
    cur = write_curriculum(tmp_path, **overrides)
    capsys.readouterr()  # the source run's progress lines
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {cur}: init_from: "), err
    expected = {
        "other-network": "does not fit this curriculum's agent: its policy '",
        "missing": f"no such run directory or checkpoint file: {tmp_path / 'source'}",
        "with-warm-start": "expected one of init_from (a trained run) and warm_start (demonstrations)",
    }[case]
    assert expected in err[0]
    assert not (tmp_path / "run").exists()


def test_unknown_agent_and_bad_yaml_in_curriculum(tmp_path, capsys):
    cur = write_curriculum(tmp_path, agent="agents/nope.yaml")
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: {cur}: agent: file not found: {tmp_path / 'agents/nope.yaml'}"]
    assert not (tmp_path / "run").exists()  # nothing written for bad input
    cur = write_curriculum(tmp_path)
    (tmp_path / "agent.yaml").write_text("name: [unclosed\n")
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run")]) == 2
    assert "agent.yaml: invalid YAML at line 2" in capsys.readouterr().err


def test_resume_before_the_first_checkpoint_starts_afresh(tmp_path, capsys):
    """A script that always passes --resume after a crash: a run killed before its first
    checkpoint starts again from step 0 with a note, and what it logged is not kept twice."""
    cur = write_curriculum(tmp_path, total_steps=400, checkpoint={"every_steps": 10_000})
    run = tmp_path / "run"
    run.mkdir()
    (run / "metrics.jsonl").write_text(json.dumps({"step": 200, "stale": True}) + "\n")  # the killed run's log
    assert main(["train", str(cur), "--run-dir", str(run), "--resume", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"note: no checkpoint.pt in {run} yet" in err and "starting the run afresh" in err
    steps = [m["step"] for m in read_jsonl(run / "metrics.jsonl")]
    assert steps == [200, 400] and not any("stale" in m for m in read_jsonl(run / "metrics.jsonl"))


def test_validate_names_a_phases_own_promotion_rule(tmp_path, capsys):
    # a phase's `promotion` replaces the curriculum-wide rule for it (no `max_steps` here, so
    # this phase never moves on by time): the summary must say so, not show only the global rule
    own = {"threshold": 1.0, "window": 50}
    cur = write_curriculum(tmp_path, phases=[{"task": "task.yaml", "promotion": own}, {"task": "task.yaml"}])
    assert main(["validate", str(cur)]) == 0
    phases = [line for line in capsys.readouterr().out.splitlines() if line.strip().startswith("phase ")]
    assert phases[0].endswith("; this phase: promote at success >= 1 over 50 episodes (min 0 steps)")
    assert "this phase" not in phases[1]


def test_resume_with_other_curriculum_is_refused(tmp_path, capsys):
    cur = write_curriculum(tmp_path, total_steps=200)
    train(cur, run_dir=tmp_path / "run", progress=False)
    other = write_curriculum(tmp_path, total_steps=200, promotion={"threshold": 0.5, "window": 4})
    assert main(["train", str(other), "--run-dir", str(tmp_path / "run"), "--resume"]) == 2
    assert "differs from the curriculum/agent of the run" in capsys.readouterr().err


def test_a_run_saved_before_a_schema_field_was_added_still_resumes(tmp_path):
    # a checkpoint from an older taskforge lacks fields added since (here: the Ray settings and
    # the MPC section, whose defaults the current schema fills in); that is the same run
    cur = write_curriculum(tmp_path, total_steps=1200)
    run = tmp_path / "run"
    train(cur, run_dir=run, steps=1200, stop_at=600, progress=False)
    state = load_checkpoint(run / "checkpoint.pt")
    del state["config"]["agent"]["runtime"]["ray_max_restarts"], state["config"]["agent"]["mpc"]
    save_checkpoint(state, run / "checkpoint.pt")
    train(cur, run_dir=run, resume=True, progress=False)
    assert load_checkpoint(run / "final.pt")["agent"]["global_step"] == 1200


def test_asymmetric_critic_trains_on_meta_world_privileged_features(tmp_path):
    agent = {**AGENT, "asymmetric_critic": True, "runtime": {"vector": "sharded", "workers": 2}}
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump(agent))
    doc = {"name": "asym", "agent": "agent.yaml", "total_steps": 400,
           "phases": [{"task": str(ROOT / "tasks/metaworld/pick_place.yaml"), "stages": ["reach"]}],
           "evaluation": {"every_steps": 10_000}}
    (tmp_path / "cur.yaml").write_text(yaml.safe_dump(doc))
    run = train(tmp_path / "cur.yaml", run_dir=tmp_path / "run", progress=False)
    policy = load_checkpoint(run / "final.pt")["agent"]["policy"]
    actor_in = next(v for k, v in policy.items() if k.startswith("actor") and k.endswith("weight")).shape[1]
    critic_in = next(v for k, v in policy.items() if k.startswith("critic") and k.endswith("weight")).shape[1]
    assert actor_in == 39 + 6 and critic_in > actor_in + 6  # obs (+ relative positions) + velocity, goal and the physics draws


def test_asymmetric_critic_without_privileged_features_is_a_clear_error(tmp_path, capsys):
    cur = write_curriculum(tmp_path)
    (tmp_path / "agent.yaml").write_text(yaml.safe_dump({**AGENT, "asymmetric_critic": True}))
    assert main(["train", str(cur), "--run-dir", str(tmp_path / "run")]) == 2
    assert "asymmetric_critic: the curriculum's backends expose no privileged features" in capsys.readouterr().err


def test_evaluating_sub_tasks_in_turn_on_shared_envs_matches_each_alone():
    """An MT10 evaluation plays each sub-task on one set of envs (fresh ones per sub-task built
    400 Meta-World envs per evaluation): a row must not depend on the rows played before it
    on those envs, and each row must play its own sub-task, recording where each trial's goal
    and object began."""
    mt10 = TASKS / "metaworld/mt10.yaml"
    spec = agent_spec(policy={"hidden_sizes": [32, 32]}, ppo=SMALL_PPO, runtime={"vector": "sync", "update_threads": 1})
    agent = PPOAgent(spec, Box(-np.inf, np.inf, (39 + 10,), np.float32), Box(-1.0, 1.0, (4,), np.float32), seed=0)
    task = load_task(mt10)
    rows = evaluate_rows(agent, task, mt10, [("solve", "reach-v3"), ("solve", "window-open-v3")], "test", trials=3,
                         seed=7, parallel=2, stop_on_success=True)
    alone = evaluate(agent, task, mt10, "solve", "test", 3, sub_task="window-open-v3", seed=7, parallel=2, stop_on_success=True)
    assert [r.task for r in rows] == ["reach-v3", "window-open-v3"]
    assert rows[1].returns == alone.returns and rows[1].lengths == alone.lengths
    assert rows[0].returns != rows[1].returns

    # each trial records where its goal and object began: those of a fresh env reset as the trial was
    env = TaskEnv(task, mt10, stage="solve", split="test")
    try:
        for row in rows:
            trials = row.as_dict()["per_trial"]
            for t in trials:
                env.reset(seed=t["seed"], options={"stage": "solve", "task": row.task, "goal_index": t["goal"]})
                for name in ("goal_pos", "object_pos"):
                    assert t[name] == pytest.approx(env.features()[name], abs=1e-4)
            assert len({tuple(t["goal_pos"]) for t in trials}) == 3  # three goals, three places
    finally:
        env.close()


def test_an_evaluation_records_each_trials_goal_and_seed_with_its_own_outcome(tmp_path, capsys):
    """Trials end out of order when episodes end at success: the per-goal record must pair each
    outcome with the trial that played it (replaying trial n alone gives its row), and name the
    goals that no episode reached (printed by `taskforge eval` under its table)."""
    upright = {"name": "upright", "rewards": [{"term": "native"}],
               "success": {"all": [{"feature": "native_reward", "above": -1.0}]}}
    task_file = tmp_path / "task.yaml"
    task_file.write_text(yaml.safe_dump({**TASK, "stages": [upright]}))
    task = load_task(task_file)
    agent = PPOAgent(agent_spec(policy={"hidden_sizes": [32, 32]}, ppo=SMALL_PPO, runtime={"vector": "sync"}),
                     Box(-np.inf, np.inf, (3,), np.float32), Box(-1.0, 1.0, (1,), np.float32), seed=0)
    result = evaluate(agent, task, task_file, "upright", "test", 12, seed=40, parallel=3, stop_on_success=True)
    lengths = [length for (length,) in result.lengths]
    assert len(set(lengths)) > 2 and lengths != sorted(lengths)  # trials did end out of order
    row = result.as_dict()
    trials = row["per_trial"]
    assert [t["seed"] for t in trials] == list(range(40, 52))
    assert [t["goal"] for t in trials] == [n % 10 for n in range(12)]  # 10 test goals, then round again
    for n in (0, 5, 11):
        alone = evaluate(agent, task, task_file, "upright", "test", n + 1, seed=40, parallel=1, stop_on_success=True)
        replay = alone.as_dict()["per_trial"][-1]
        # a batch of one rounds the policy's matmuls differently from a batch of three
        assert replay["returns"] == pytest.approx(trials[n]["returns"], rel=1e-6)
        assert {**replay, "returns": None} == {**trials[n], "returns": None}
    missed = sorted({t["goal"] for t in trials if not any(t["successes"])})
    assert row["missed_goals"] == missed and 0 < len(missed) < 10
    assert row["successes"] == sum(t["successes"][0] for t in trials)

    table = format_table({"checkpoint": "run", "step": 0, "split": "test", "trial_episodes": 1, "rows": [row]})
    assert table.splitlines()[-1] == f"missed goals, pendulum-two-stage upright: {', '.join(map(str, missed))}"
