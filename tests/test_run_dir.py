"""The run directory (`taskforge.run`): checkpoints load without running code, broken files
and failed writes are one clear line, and a run's agent is rebuilt the way training built it."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys

import pytest
import torch

from taskforge.cli import main
from taskforge.run import RunDir, load_checkpoint, load_run, save_checkpoint
from taskforge.spec import SpecError
from taskforge.training import train
from tests.conftest import ROOT
from tests.test_training import write_curriculum


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run")
    return train(write_curriculum(folder, total_steps=400), run_dir=folder / "run", progress=False)


class Payload:
    """Unpickling this runs code: what a malicious checkpoint would carry."""

    def __reduce__(self):
        return (os.system, ("touch pwned",))


def test_a_checkpoint_carrying_a_pickled_object_is_refused(finished_run, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    state = torch.load(finished_run / "final.pt", weights_only=True)
    state["extra"] = Payload()
    bad = tmp_path / "bad.pt"
    torch.save(state, bad)
    assert main(["eval", str(bad), "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {bad}: refused: it holds more than tensors"), err
    assert "posix.system" in err[0]
    assert not (tmp_path / "pwned").exists()


@pytest.mark.parametrize("damage", ["truncated", "not a checkpoint"])
def test_a_broken_checkpoint_is_one_line_naming_the_file(finished_run, tmp_path, capsys, damage):
    bad = tmp_path / "checkpoint.pt"
    data = (finished_run / "final.pt").read_bytes()
    bad.write_bytes(data[: len(data) // 2] if damage == "truncated" else b"hello")
    assert main(["eval", str(bad), "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {bad}: not a readable checkpoint (truncated or corrupt"), err


def test_a_failed_checkpoint_write_keeps_the_previous_one(finished_run, tmp_path, monkeypatch):
    """A full disk mid-save (simulated: the write itself fails with ENOSPC): one clear error, and
    the previous checkpoint is untouched and still loads."""
    path = tmp_path / "checkpoint.pt"
    state = load_checkpoint(finished_run / "checkpoint.pt")
    save_checkpoint(state, path)
    before = path.read_bytes()

    def full(obj, f, *args, **kwargs):
        f.write(b"partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(torch, "save", full)
    with pytest.raises(SpecError) as exc:
        save_checkpoint(state, path)
    assert str(exc.value).startswith(f"{path}: could not write the checkpoint (No space left on device)")
    assert path.read_bytes() == before and not list(tmp_path.glob(".*.tmp"))


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_an_unwritable_run_directory_is_one_line(finished_run, tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o500)
    with pytest.raises(SpecError, match="could not write the checkpoint"):
        save_checkpoint(load_checkpoint(finished_run / "checkpoint.pt"), folder / "checkpoint.pt")


def test_load_run_rebuilds_the_trained_agent(finished_run):
    """The same networks and statistics as the run saved: evaluation and rendering load this way."""
    run = load_run(finished_run)
    assert run.checkpoint == RunDir(finished_run).final
    saved = load_checkpoint(run.checkpoint)["agent"]["policy"]
    for key, value in run.agent.state_dict()["policy"].items():
        assert torch.equal(value, saved[key]), key
    assert [stages for _, _, stages in run.phases] == [["easy", "hard"]]
    with pytest.raises(SpecError, match="no final.pt or checkpoint.pt in this run directory"):
        load_run(finished_run.parent)


def test_run_dir_reports_progress_without_a_checkpoint(finished_run, tmp_path):
    """A finished benchmark run is committed with its metrics and without checkpoints."""
    kept = tmp_path / "kept"
    kept.mkdir()
    for name in ("metrics.jsonl", "events.jsonl", "config.json"):
        (kept / name).write_bytes((finished_run / name).read_bytes())
    assert RunDir(kept).steps_done() == RunDir(finished_run).steps_done() == 400
    assert RunDir(tmp_path / "new").steps_done() == 0


def test_reward_terms_are_logged_per_episode(tmp_path):
    """Each term's weighted sum over an episode (`episode_reward/<term>`): what a user tunes a
    stage's weights with. Meta-World reach: 150-step episodes of two terms."""
    doc = {"name": "terms", "agent": "agent.yaml", "total_steps": 600,
           "phases": [{"task": str(ROOT / "tasks/metaworld/pick_place.yaml"), "stages": ["reach"]}],
           "evaluation": {"every_steps": 10_000}, "checkpoint": {"every_steps": 10_000}}
    write_curriculum(tmp_path)
    (tmp_path / "cur.yaml").write_text(json.dumps(doc))
    run = train(tmp_path / "cur.yaml", run_dir=tmp_path / "run", progress=False)
    records = [m for m in RunDir(run).read_metrics() if m.get("episodes")]
    assert records, "no episode finished"
    for m in records:
        reach, effort = m["episode_reward/tcp_to_object"], m["episode_reward/action_l2"]
        assert 0.0 < reach <= 150.0 and -0.01 * 150 * 4 <= effort < 0.0  # weight 1 x [0, 1]; -0.01 x |a|² <= 4
        assert m["return_mean"] == pytest.approx(reach + effort, rel=1e-4)


def test_ctrl_c_while_importing_prints_no_traceback():
    """A Ctrl-C that lands while the command is still importing (MuJoCo, torch: the first half
    second): made deterministic by raising KeyboardInterrupt from the import of mujoco itself, as
    the signal would, instead of racing a timer against the machine's load."""
    code = (
        "import builtins, sys\n"
        "real_import = builtins.__import__\n"
        "def interrupted(name, *args, **kwargs):\n"
        "    if name == 'mujoco':\n"
        "        raise KeyboardInterrupt\n"
        "    return real_import(name, *args, **kwargs)\n"
        "builtins.__import__ = interrupted\n"
        f"sys.argv = ['taskforge', 'validate', {str(ROOT / 'curricula/pick_place.yaml')!r}]\n"
        "from taskforge.__main__ import run\n"
        "run()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 130 and proc.stderr.strip() == "interrupted", proc.stderr


def test_a_reader_that_closes_the_pipe_gets_no_traceback():
    """`taskforge validate x.yaml | head -1`: head exits after one line and the next print hits a
    closed pipe; the command must stop quietly (status 141, as a tool killed by SIGPIPE). Here the
    pipe's read end is closed before the command starts, so its first print fails, deterministically."""
    cmd = [sys.executable, "-m", "taskforge", "validate", str(ROOT / "curricula/pick_place.yaml")]
    read_end, write_end = os.pipe()
    os.close(read_end)  # nobody will ever read: every write fails with EPIPE
    proc = subprocess.run(cmd, cwd=ROOT, stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=120)
    os.close(write_end)
    assert proc.returncode == 141 and "Traceback" not in proc.stderr, proc.stderr
