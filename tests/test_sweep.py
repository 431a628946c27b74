"""`taskforge sweep`: a small real sweep on a local Ray instance (2 variants x 2 seeds of a
Pendulum curriculum), its table, resuming, and one-line errors for bad sweep files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

ray = pytest.importorskip("ray")

from taskforge.cli import main  # noqa: E402
from taskforge.run import RunDir  # noqa: E402
from taskforge.spec import SpecError  # noqa: E402
from taskforge.sweep import plan_sweep, run_sweep, summarize_seeds  # noqa: E402
from taskforge.training import train  # noqa: E402
from tests.test_sharded_vector import TASK  # noqa: E402

STEPS = 6 * 2 * 64
NOISY = {"randomization": {"observation_noise": {"per_step": {"dist": "normal", "std": 0.5}}}}
CLEAN = {"randomization": {"observation_noise": {"per_step": None}}}


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    yield
    ray.shutdown()


def write_sweep(folder: Path, **changes) -> Path:
    (folder / "task.yaml").write_text(yaml.safe_dump(TASK.model_dump(mode="json", exclude_unset=True)))
    agent = {"name": "tiny", "ppo": {"num_envs": 2, "rollout_steps": 64, "num_minibatches": 2, "update_epochs": 1},
             "runtime": {"vector": "sync"}}
    (folder / "agent.yaml").write_text(yaml.safe_dump(agent))
    curriculum = {"name": "tiny", "agent": "agent.yaml", "total_steps": 10 * STEPS, "phases": [{"task": "task.yaml"}],
                  "evaluation": {"every_steps": 2 * 64 * 3, "episodes": 2}, "checkpoint": {"every_steps": 2 * 64 * 2}}
    (folder / "curriculum.yaml").write_text(yaml.safe_dump(curriculum))
    sweep = {
        "name": "tiny-sweep",
        "curriculum": "curriculum.yaml",
        "seeds": [0, 1],
        "total_steps": STEPS,
        "variants": [{"name": "as is"}, {"name": "Noisy obs", "task": NOISY, "agent": {"policy": {"hidden_sizes": [8]}}}],
        "evaluation": {"episodes": 3, "conditions": [{"name": "clean"}, {"name": "noisy", "task": NOISY}]},
        **changes,
    }
    path = folder / "sweep.yaml"
    path.write_text(yaml.safe_dump(sweep, sort_keys=False))
    return path


def test_seed_summary_is_mean_t_interval_median_and_sorted_values():
    cell = summarize_seeds([0.9, 0.5, 0.7])
    assert cell["mean"] == pytest.approx(0.7) and cell["median"] == 0.7 and cell["sorted"] == [0.5, 0.7, 0.9]
    assert cell["ci95_half_width"] == pytest.approx(4.302653 * 0.2 / np.sqrt(3), rel=1e-5)  # t(0.975, 2) * s / sqrt(n)
    assert summarize_seeds([0.4])["ci95_half_width"] is None


def test_a_sweep_trains_every_variant_and_seed_and_tables_them(tmp_path, capsys):
    sweep = write_sweep(tmp_path)
    out = tmp_path / "out"
    assert main(["sweep", str(sweep), "--out", str(out)]) == 0
    assert "| training environment | clean | noisy |" in capsys.readouterr().out

    # each trial is an ordinary run on the variant's files: the override reached its task and agent
    variant = out / "noisy-obs"
    assert yaml.safe_load((variant / "task_0.yaml").read_text())["randomization"] == NOISY["randomization"]
    config = json.loads(RunDir(variant / "seed1").config.read_text())
    assert config["seed"] == 1 and config["agent"]["policy"]["hidden_sizes"] == [8]
    assert config["phases"][0]["task"]["randomization"]["observation_noise"]["per_step"]["std"] == 0.5
    plain = json.loads(RunDir(out / "as-is" / "seed0").config.read_text())
    assert plain["phases"][0]["task"]["randomization"]["observation_noise"]["per_step"]["std"] == 0.1

    table = json.loads((out / "table.json").read_text())
    assert table["conditions"] == ["clean", "noisy"] and [r["variant"] for r in table["rows"]] == ["as is", "Noisy obs"]
    for row in table["rows"]:
        assert row["steps"] == [STEPS]
        for condition in ("clean", "noisy"):
            cell = row["cells"][condition]
            evals = [json.loads((out / ("as-is" if row["variant"] == "as is" else "noisy-obs") / f"seed{s}" / "sweep_eval.json")
                                .read_text())["conditions"][condition] for s in (0, 1)]
            assert cell["per_seed"] == {"0": evals[0]["success_rate"], "1": evals[1]["success_rate"]}
            assert all(e["episodes"] == 3 for e in evals)
            assert cell["mean"] == pytest.approx(np.mean([e["success_rate"] for e in evals]))
    assert table["machine"]["cores"] >= 1 and table["command"]
    assert (out / "table.md").read_text().count("\n| ") == 3  # header + 2 variants
    assert (out / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # again without --resume: refused, nothing touched; with it: every trial skipped
    final = RunDir(out / "as-is" / "seed0").final
    stamp = final.stat().st_mtime_ns
    assert main(["sweep", str(sweep), "--out", str(out)]) == 2
    assert "pass --resume" in capsys.readouterr().err
    run_sweep(sweep, out=out, resume=True, echo=lambda line: None)
    assert final.stat().st_mtime_ns == stamp


def test_an_interrupted_trial_resumes_from_its_checkpoint(tmp_path):
    sweep = write_sweep(tmp_path, variants=[{"name": "only"}], seeds=[3])
    out = tmp_path / "out"
    plan = plan_sweep(sweep, out)
    from taskforge.sweep.plan import write_plan

    write_plan(plan)
    (trial,) = plan.trials
    train(trial.curriculum_file, run_dir=trial.run_dir, seed=3, steps=STEPS, stop_at=STEPS // 2, progress=False)
    paused = json.loads(RunDir(trial.run_dir).metrics.read_text().splitlines()[-1])["step"]
    assert paused < STEPS
    heard: list[str] = []
    run_sweep(sweep, out=out, resume=True, echo=heard.append)
    steps = [json.loads(line)["step"] for line in RunDir(trial.run_dir).metrics.read_text().splitlines()]
    assert steps == sorted(set(steps)) and steps[-1] == STEPS and paused in steps  # continued, not restarted
    assert any("[1/1] only, seed 3" in line for line in heard)


@pytest.mark.parametrize("changes, where", [
    ({"variants": [{"name": "x", "task": {"randomization": {"physics": [{"target": "nonsense", "op": "scale"}]}}}]},
     "variants[0].task.randomization.physics[0]"),
    ({"variants": [{"name": "x", "agent": {"ppo": {"num_envs": 0}}}]}, "variants[0].agent.ppo.num_envs"),
    ({"variants": [{"name": "x"}, {"name": "x"}]}, "variants"),
    ({"variants": [{"name": "a b"}, {"name": "a-b"}]}, "variants[1].name"),
    ({"evaluation": {"stage": "nope", "conditions": [{"name": "c"}]}}, "evaluation.stage"),
    ({"evaluation": {"conditions": [{"name": "c", "task": {"max_episode_steps": -1}}]}}, "evaluation.conditions[0].task.max_episode_steps"),
    ({"curriculum": "missing.yaml"}, "curriculum"),
])
def test_bad_sweep_files_are_one_line_errors_at_the_sweep_files_field(tmp_path, capsys, changes, where):
    sweep = write_sweep(tmp_path, **changes)
    with pytest.raises(SpecError) as caught:
        plan_sweep(sweep)
    assert any(str(issue).startswith(f"{sweep}: {where}") for issue in caught.value.issues), caught.value.issues
    assert main(["validate", str(sweep)]) == 2
    err = capsys.readouterr().err
    assert f"{sweep}: {where}" in err and "Traceback" not in err


def test_a_base_curriculum_that_is_itself_a_variant_elsewhere_resolves_its_tasks(tmp_path):
    """The sweep's curriculum has a `base:` in another folder: its phases' task paths are the
    base's, relative to the base; a variant's task override must still find them."""
    write_sweep(tmp_path)
    (tmp_path / "more").mkdir()
    (tmp_path / "more" / "longer.yaml").write_text(yaml.safe_dump({"base": "../curriculum.yaml", "name": "longer"}))
    sweep = tmp_path / "more" / "sweep.yaml"
    sweep.write_text(yaml.safe_dump({
        "name": "nested", "curriculum": "longer.yaml", "seeds": [0],
        "variants": [{"name": "noisy", "task": NOISY}], "evaluation": {"conditions": [{"name": "as trained"}]}}))
    plan = plan_sweep(sweep, tmp_path / "out")
    from taskforge.sweep.plan import write_plan

    write_plan(plan)
    task = yaml.safe_load((tmp_path / "out" / "noisy" / "task_0.yaml").read_text())
    assert task["base"] == str((tmp_path / "task.yaml").resolve())
