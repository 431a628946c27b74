"""`taskforge inspect`: a task's model names by kind and a scripted episode's per-step features
and rewards, so thresholds and physics `names:` are written from data."""

from __future__ import annotations

import csv

from taskforge.cli import main
from tests.conftest import ROOT

PICK_PLACE = ROOT / "tasks/metaworld/pick_place.yaml"


def test_inspect_lists_every_name_and_traces_the_scripted_episode(tmp_path, capsys):
    out = tmp_path / "trace.csv"
    assert main(["inspect", str(PICK_PLACE), "--stage", "pick", "--csv", str(out)]) == 0
    text = capsys.readouterr().out
    bodies = next(line for line in text.splitlines() if line.strip().startswith("bodies ("))
    count = int(bodies.split("(")[1].split(")")[0])
    assert count > 17 and "obj" in text and "objGeom" in text  # the puck's names, beyond the first robot parts
    assert "scripted policy planner:pick: succeeds at step" in text
    rows = list(csv.DictReader(out.open()))
    assert rows[0]["step"] == "0" and {"object_grasped", "object_height", "reward/lift", "reward", "success"} <= rows[0].keys()
    first = next(r for r in rows if r["success"] == "1")
    assert float(first["object_height"]) > 0.04 and float(first["object_grasped"]) == 1.0  # the stage's own thresholds
    total = sum(float(rows[5][k]) for k in rows[5] if k.startswith("reward/"))
    assert abs(total - float(rows[5]["reward"])) < 1e-6  # the terms add up to the reward


def test_inspect_traces_every_shipped_stage(capsys):
    """Every stage's terms and conditions have a column, `stage_success` (added by the env, not
    the backend) included."""
    for stage in ("reach", "push", "pick", "place"):
        assert main(["inspect", str(PICK_PLACE), "--stage", stage, "--every", "100"]) == 0
    assert "reward/stage_success" in capsys.readouterr().out


def test_a_bad_physics_name_points_to_inspect(tmp_path, capsys):
    import yaml

    doc = yaml.safe_load(PICK_PLACE.read_text())
    doc["randomization"]["physics"][0]["names"] = ["no_such_body"]
    (tmp_path / "task.yaml").write_text(yaml.safe_dump(doc))
    assert main(["validate", str(tmp_path / "task.yaml")]) == 2
    assert f"(every name: taskforge inspect {tmp_path / 'task.yaml'})" in capsys.readouterr().err
