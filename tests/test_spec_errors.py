"""A catalogue of bad files: each yields exactly one line naming file, field path and what was
expected, exit code 2 and no traceback."""

from __future__ import annotations

import copy
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from taskforge.cli import main
from tests.conftest import PICK_PLACE, ROOT

BASE = yaml.safe_load(PICK_PLACE.read_text())


def _set(path: list[Any], value: Any) -> Callable[[dict], None]:
    def mutate(doc: dict) -> None:
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return mutate


def _delete(path: list[Any]) -> Callable[[dict], None]:
    def mutate(doc: dict) -> None:
        node = doc
        for key in path[:-1]:
            node = node[key]
        del node[path[-1]]

    return mutate


# (id, mutation, expected field path, expected fragment of the message)
CATALOGUE = [
    ("weight-not-a-number", _set(["stages", 2, "rewards", 0, "weight"], "heavy"), "stages[2].rewards[0].weight", "valid number"),
    ("unknown-term", _set(["stages", 1, "rewards", 0, "term"], "tcp_to_objet"), "stages[1].rewards[0].term", "did you mean 'tcp_to_object'"),
    ("unknown-stage-key", _set(["stages", 0, "max_episode_step"], 10), "stages[0].max_episode_step", "did you mean 'max_episode_steps'"),
    ("unknown-top-key", _set(["stagez"], []), "stagez", "did you mean 'stages'"),
    # one mistake, one line: a block in another shape is not a missing field plus two unknown ones
    ("misshapen-success", _set(["stages", 0, "success"], {"feature": "tcp_to_object_distance", "below": 0.03}),
     "stages[0].success", "expected the field 'all', got 'below', 'feature'"),  # the file's key order (sorted by the dump)
    # names are ranked by their parts: the object (here a handle) to the goal, not the tool
    ("feature-by-parts", _set(["stages", 3, "success", "all", 0, "feature"], "handle_to_goal_distance"),
     "stages[3].success.all[0].feature", "did you mean 'object_to_goal_distance'"),
    ("negative-std", _set(["randomization", "observation_noise", "per_step", "std"], -1), "randomization.observation_noise.per_step.std", "greater than or equal to 0"),
    ("min-above-max", _set(["randomization", "physics", 0, "low"], 2.0), "randomization.physics[0]", "'low' (2.0) must be <= 'high' (1.5)"),
    ("loguniform-nonpositive", _set(["randomization", "physics", 2, "low"], 0.0), "randomization.physics[2]", "loguniform distribution needs 'low' > 0"),
    ("unknown-dist", _set(["randomization", "physics", 0, "dist"], "gaussian"), "randomization.physics[0].dist", "expected one of loguniform, normal, uniform"),
    ("unknown-param", _set(["stages", 0, "rewards", 0, "params", "margn"], 0.1), "stages[0].rewards[0].params.margn", "did you mean 'margin'"),
    ("bad-kernel", _set(["stages", 0, "rewards", 0, "params", "kernel"], "gauss"), "stages[0].rewards[0].params.kernel", "did you mean 'gaussian'"),
    ("negative-margin", _set(["stages", 0, "rewards", 0, "params", "margin"], -0.1), "stages[0].rewards[0].params.margin", "greater than 0"),
    ("unknown-feature", _set(["stages", 0, "success", "all", 0, "feature"], "tcp_to_obj_distance"), "stages[0].success.all[0].feature", "did you mean 'tcp_to_object_distance'"),
    ("vector-feature", _set(["stages", 0, "success", "all", 0, "feature"], "tcp_pos"), "stages[0].success.all[0].feature", "is a vector"),
    ("condition-without-bound", _set(["stages", 0, "success", "all", 0], {"feature": "object_height"}), "stages[0].success.all[0]", "needs 'below' and/or 'above'"),
    ("unknown-env", _set(["backend", "env"], "pick-place-v2"), "backend.env", "did you mean 'pick-place-v3'"),
    ("unknown-backend", _set(["backend", "type"], "metawrld"), "backend.type", "did you mean 'metaworld'"),
    ("unknown-backend-key", _set(["backend", "evn"], 1), "backend.evn", "expected one of env, task_id_in_obs, task_set, type (did you mean 'env'?)"),
    ("missing-stages", _delete(["stages"]), "stages", "required field is missing"),
    ("duplicate-stage", _set(["stages", 1, "name"], "reach"), "stages", "repeated: reach"),
    ("goal-count-too-large", _set(["goals", "test", "count"], 500), "goals.test.count", "ML1 has 50 goals per split"),
    ("term-needs-missing-feature", lambda d: d.update(
        backend={"type": "gymnasium", "env": "Pendulum-v1"}, randomization={},
        stages=[{**d["stages"][0], "success": {"all": [{"feature": "native_return", "above": 0}]}}]), "stages[0].rewards[0].term", "reads tcp_to_object_distance, which the gymnasium backend does not provide"),
    ("latency-reversed", _set(["randomization", "action_latency"], {"min_steps": 3, "max_steps": 1}), "randomization.action_latency", "'min_steps' (3) must be <= 'max_steps' (1)"),
    ("height-scale-without-height", _set(["stages", 1, "goal"], {"height_scale": 0.5}), "stages[1].goal", "set height to a number or 'object' (got 'keep')"),
    ("distance-scale-range", _set(["stages", 1, "goal", "distance_scale"], 1.5), "stages[1].goal.distance_scale", "less than or equal to 1"),
    ("unmatched-body-name", _set(["randomization", "physics", 0, "names"], ["no_such_body"]), "randomization.physics[0].names[0]", "matches no body"),
    ("gravity-with-names", _set(["randomization", "physics", 4, "names"], ["world"]), "randomization.physics[4].names", "gravity has no named elements"),
]


def _run_validate(path: Path, capsys, kind: str = "task") -> tuple[int, list[str]]:
    code = main(["validate", "--kind", kind, str(path)])
    err = capsys.readouterr().err
    return code, [line for line in err.splitlines() if line]


@pytest.mark.parametrize("case_id,mutate,field,fragment", CATALOGUE, ids=[c[0] for c in CATALOGUE])
def test_bad_task_file_gives_one_clear_line(case_id, mutate, field, fragment, tmp_path, capsys):
    doc = copy.deepcopy(BASE)
    mutate(doc)
    path = tmp_path / f"{case_id}.yaml"
    path.write_text(yaml.safe_dump(doc))
    code, lines = _run_validate(path, capsys)
    assert code == 2
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: {path}: {field}: "), lines[0]
    assert fragment in lines[0], lines[0]


@pytest.mark.parametrize(
    "mutations,fields",
    [
        # two schema mistakes
        ([(["stages", 3, "rewards", 0, "weight"], "x"), (["goals", "seed"], "zero")],
         ["goals.seed", "stages[3].rewards[0].weight"]),
        # two registry mistakes (checked once the schema passes)
        ([(["stages", 1, "rewards", 0, "term"], "nope"), (["stages", 2, "success", "all", 0, "feature"], "grip")],
         ["stages[1].rewards[0].term", "stages[2].success.all[0].feature"]),
    ],
)
def test_each_mistake_gets_its_own_line(mutations, fields, tmp_path, capsys):
    doc = copy.deepcopy(BASE)
    for path, value in mutations:
        _set(path, value)(doc)
    path = tmp_path / "two.yaml"
    path.write_text(yaml.safe_dump(doc))
    code, lines = _run_validate(path, capsys)
    assert code == 2
    assert sorted(line.split(": ")[2] for line in lines) == fields


@pytest.mark.parametrize(
    "text,fragment",
    [("name: x\nstages: [\n", "invalid YAML at line 3"), ("- a\n- b\n", "expected a mapping at the top level")],
)
def test_unparseable_yaml(text, fragment, tmp_path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    code, lines = _run_validate(path, capsys)
    assert code == 2 and len(lines) == 1 and fragment in lines[0]


def test_missing_file(tmp_path, capsys):
    code, lines = _run_validate(tmp_path / "absent.yaml", capsys)
    assert code == 2 and lines == [f"error: {tmp_path / 'absent.yaml'}: no such file; expected a YAML file"]


def test_curriculum_with_bad_references(tmp_path, capsys):
    doc = yaml.safe_load((ROOT / "curricula/pick_place.yaml").read_text())
    doc["agent"] = str(ROOT / "agents/missing.yaml")
    doc["phases"][0]["task"] = str(ROOT / "tasks/metaworld/pick_place.yaml")
    doc["phases"][0]["stages"] = ["reach", "pik"]
    path = tmp_path / "cur.yaml"
    path.write_text(yaml.safe_dump(doc))
    code, lines = _run_validate(path, capsys, kind="curriculum")
    assert code == 2
    assert lines[0] == f"error: {path}: agent: file not found: {ROOT / 'agents/missing.yaml'}"
    assert lines[1].startswith(f"error: {path}: phases[0].stages[1]: no stage 'pik'")
    assert "did you mean 'pick'" in lines[1]


def test_bad_agent_value(tmp_path, capsys):
    doc = yaml.safe_load((ROOT / "agents/ppo.yaml").read_text())
    doc["ppo"]["gamma"] = 1.5
    doc["policy"]["type"] = "transformer"
    path = tmp_path / "agent.yaml"
    path.write_text(yaml.safe_dump(doc))
    code, lines = _run_validate(path, capsys, kind="agent")
    assert code == 2
    assert {line.split(": ")[2] for line in lines} == {"ppo.gamma", "policy.type"}


def test_console_script_prints_no_traceback(tmp_path):
    doc = copy.deepcopy(BASE)
    _set(["stages", 0, "rewards", 0, "term"], "bogus")(doc)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    proc = subprocess.run(
        [sys.executable, "-m", "taskforge.cli", "validate", str(path)], capture_output=True, text=True, cwd=ROOT
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.count("\n") == 1 and "stages[0].rewards[0].term" in proc.stderr
