"""Task and agent variants written as `base:` + the fields that differ: merged like the full
file would be, paths kept pointing at the same files, and a bad `base:` is one clear line."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from taskforge.cli import main
from taskforge.spec import SpecError, load_agent_spec, load_task_spec, read_task_yaml
from tests.conftest import PICK_PLACE, ROOT

XARM = ROOT / "tasks/xarm7"


def _write(path: Path, doc: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_variant_merges_mappings_and_replaces_everything_else(tmp_path):
    base = yaml.safe_load(PICK_PLACE.read_text())
    _write(tmp_path / "base.yaml", base)
    only_place = [s for s in base["stages"] if s["name"] == "place"]
    variant = _write(tmp_path / "variant.yaml", {
        "base": "base.yaml",
        "name": "variant",
        "backend": {"type": "metaworld", "env": "pick-place-v3"},
        "randomization": {"object_start": "random", "observation_noise": {"per_episode": None}},
        "stages": only_place,
    })
    merged = read_task_yaml(variant)
    assert "base" not in merged
    assert merged["name"] == "variant"
    assert merged["stages"] == only_place                      # a list replaces the base's whole
    assert merged["randomization"]["object_start"] == "random"  # a mapping merges key by key...
    assert merged["randomization"]["physics"] == base["randomization"]["physics"]  # ...keeping the rest
    assert merged["randomization"]["observation_noise"] == {   # null replaces too
        "per_step": base["randomization"]["observation_noise"]["per_step"], "per_episode": None}
    assert merged["goals"] == base["goals"]
    spec = load_task_spec(variant)
    assert spec.stage_names == ["place"] and spec.randomization.observation_noise.per_episode is None


def test_bases_chain(tmp_path):
    _write(tmp_path / "a.yaml", yaml.safe_load(PICK_PLACE.read_text()))
    _write(tmp_path / "b.yaml", {"base": "a.yaml", "name": "b", "max_episode_steps": 400})
    c = _write(tmp_path / "sub/c.yaml", {"base": "../b.yaml", "name": "c", "goals": {"seed": 7}})
    spec = load_task_spec(c)
    assert (spec.name, spec.max_episode_steps, spec.goals.seed, spec.goals.test.count) == ("c", 400, 7, 50)


def test_paths_in_the_base_keep_naming_the_same_file(tmp_path):
    base = yaml.safe_load((XARM / "pick_place.yaml").read_text())
    base["backend"]["robot_model"] = "../robots/arm.xml"
    _write(tmp_path / "tasks/a/base.yaml", base)
    variant = _write(tmp_path / "tasks/b/deeper/variant.yaml", {"base": "../../a/base.yaml", "name": "v"})
    model = read_task_yaml(variant)["backend"]["robot_model"]
    assert (variant.parent / model).resolve() == (tmp_path / "tasks/robots/arm.xml").resolve()
    same_folder = _write(tmp_path / "tasks/a/v2.yaml", {"base": "base.yaml", "name": "v2"})
    assert read_task_yaml(same_folder)["backend"]["robot_model"] == "../robots/arm.xml"


@pytest.mark.parametrize("variant,changed", [
    ("pick_place_big_cube.yaml", {"cube": {"size": 0.03, "mass": 0.3}}),
    ("pick_place_low_table.yaml", {"table_height": -0.05}),
    ("pick_place_high_goals.yaml", {"goal_region": {"x": (0.30, 0.55), "y": (-0.20, 0.20), "z": (0.20, 0.40)}}),
])
def test_shipped_xarm7_variants_differ_from_their_base_only_where_they_say(variant, changed):
    base = load_task_spec(XARM / "pick_place.yaml")
    spec = load_task_spec(XARM / variant)
    expected = base.model_copy(update={
        "name": spec.name, "description": spec.description,
        "backend": base.backend.model_validate({**base.backend.model_dump(), **changed}),
    })
    assert spec == expected
    assert spec.name != base.name


def test_meta_pick_place_is_pick_place_with_the_puck_drawn_per_trial():
    base = load_task_spec(PICK_PLACE)
    meta = load_task_spec(ROOT / "tasks/metaworld/pick_place_meta.yaml")
    assert meta.randomization.object_start == "random" and base.randomization.object_start == "goal_set"
    assert meta.stages == base.stages and meta.goals == base.goals and meta.backend == base.backend
    assert meta.randomization.physics == base.randomization.physics


@pytest.mark.parametrize("base_value,fragment", [
    ("missing.yaml", "base: no such file"),
    (3, "base: expected the path of a file of the same kind"),
    ("variant.yaml", "base: 'variant.yaml' leads back to this file"),
])
def test_bad_base_is_one_line(base_value, fragment, tmp_path, capsys):
    variant = _write(tmp_path / "variant.yaml", {"base": base_value, "name": "v"})
    assert main(["validate", str(variant)]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {variant}: ") and fragment in lines[0]


def test_a_cycle_through_two_files_is_refused(tmp_path):
    _write(tmp_path / "a.yaml", {"base": "b.yaml", "name": "a"})
    b = _write(tmp_path / "b.yaml", {"base": "a.yaml", "name": "b"})
    with pytest.raises(SpecError, match="leads back to this file"):
        read_task_yaml(b)


def test_a_mistake_in_the_variant_names_the_variant(tmp_path, capsys):
    _write(tmp_path / "base.yaml", yaml.safe_load(PICK_PLACE.read_text()))
    variant = _write(tmp_path / "variant.yaml", {"base": "base.yaml", "max_episode_steps": -1})
    assert main(["validate", str(variant)]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {variant}: max_episode_steps: ")


def test_agent_preset_variant(tmp_path, capsys):
    variant = _write(tmp_path / "agents/long_bptt.yaml", {
        "base": str(ROOT / "agents/rl2.yaml"), "name": "long-bptt",
        "ppo": {"rollout_steps": 1000, "bptt_length": 1000, "num_minibatches": 4},
    })
    base = load_agent_spec(ROOT / "agents/rl2.yaml")
    spec = load_agent_spec(variant)
    assert (spec.ppo.rollout_steps, spec.ppo.bptt_length, spec.ppo.num_minibatches) == (1000, 1000, 4)
    assert spec.ppo.model_copy(update={"rollout_steps": base.ppo.rollout_steps, "bptt_length": base.ppo.bptt_length,
                                       "num_minibatches": base.ppo.num_minibatches}) == base.ppo
    assert (spec.policy, spec.rl2, spec.algo) == (base.policy, base.rl2, base.algo)
    assert main(["validate", str(variant)]) == 0  # recognised as an agent preset through its base
    assert "agent long-bptt: rl2" in capsys.readouterr().out
