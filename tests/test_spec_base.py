"""Task, agent and curriculum variants written as `base:` + the fields that differ: merged like
the full file would be, paths kept pointing at the same files, and a bad `base:` is one clear line."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from taskforge.cli import main
from taskforge.envs import load_curriculum
from taskforge.spec import SpecError, load_agent_spec, load_curriculum_spec, load_task_spec, read_task_yaml
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


@pytest.mark.parametrize("base_file, meta_file", [
    ("tasks/metaworld/pick_place.yaml", "tasks/metaworld/pick_place_meta.yaml"),
    ("tasks/metaworld/reach.yaml", "tasks/metaworld/reach_meta.yaml"),
    ("tasks/metaworld/push.yaml", "tasks/metaworld/push_meta.yaml"),
    ("tasks/xarm7/pick_place.yaml", "tasks/xarm7/pick_place_meta.yaml"),
])
def test_meta_variants_hide_the_goal_and_draw_the_object_per_trial_and_nothing_else(base_file, meta_file):
    """The PPO files observe the goal; their RL² variants hide it and draw the object per trial
    (so the object's start does not name the goal), and are otherwise the same task."""
    base = load_task_spec(ROOT / base_file)
    meta = load_task_spec(ROOT / meta_file)
    assert base.goals.observable and not meta.goals.observable
    assert meta.randomization.object_start == "random" and base.randomization.object_start == "goal_set"
    assert meta.stages == base.stages and meta.backend == base.backend
    assert meta.goals.model_copy(update={"observable": True}) == base.goals
    assert meta.randomization.model_copy(update={"object_start": "goal_set"}) == base.randomization


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


def test_curriculum_variant_in_another_folder_keeps_its_base_files(tmp_path, capsys):
    """A curriculum's agent, phase tasks and demos are relative to the file that writes them: a
    variant elsewhere must still train the base's agent on the base's tasks."""
    variant = _write(tmp_path / "bench/configs/ppo_reach.yaml", {
        "base": str(ROOT / "curricula/ml1_reach_rl2.yaml"), "name": "ppo-reach", "total_steps": 2000,
    })
    base = load_curriculum(ROOT / "curricula/ml1_reach_rl2.yaml")
    cur = load_curriculum(variant)
    assert cur.agent_file == base.agent_file and cur.agent == base.agent
    assert [p.task_file for p in cur.phases] == [p.task_file for p in base.phases]
    assert (cur.spec.name, cur.spec.total_steps, cur.spec.evaluation) == ("ppo-reach", 2000, base.spec.evaluation)
    assert main(["validate", str(variant)]) == 0  # recognised as a curriculum through its base
    assert "curriculum ppo-reach" in capsys.readouterr().out

    demos = _write(tmp_path / "curricula/with_demos.yaml", {
        "base": str(ROOT / "curricula/pick_place.yaml"),
        "warm_start": {"generate_episodes": None, "demos": "../demos/pp.npz", "phase": 0, "stage": "reach"},
    })
    deeper = _write(tmp_path / "curricula/variants/v.yaml", {"base": "../with_demos.yaml", "seed": 3})
    demos_path = load_curriculum_spec(deeper).warm_start.demos
    assert (deeper.parent / demos_path).resolve() == (tmp_path / "demos/pp.npz").resolve()
    assert load_curriculum_spec(demos).warm_start.demos == "../demos/pp.npz"


@pytest.mark.parametrize("variant,base,changed", [
    ("ml1_push_ppo.yaml", "ml1_push_rl2.yaml", {"name", "agent"}),
    ("ml1_reach_ppo.yaml", "../../curricula/ml1_reach_rl2.yaml", {"name", "agent", "total_steps", "replay"}),
    ("ml1_reach_rl2_whole_trial.yaml", "../../curricula/ml1_reach_rl2.yaml", {"name", "agent", "total_steps", "replay"}),
])
def test_benchmark_baselines_differ_from_their_base_only_where_they_say(variant, base, changed):
    """The memoryless baselines must play RL²'s task with RL²'s evaluation; as variants they cannot drift."""
    configs = ROOT / "benchmarks/configs"
    spec, base_spec = load_curriculum(configs / variant), load_curriculum(configs / base)
    assert [(p.task_file, p.stages) for p in spec.phases] == [(p.task_file, p.stages) for p in base_spec.phases]
    same = set(type(spec.spec).model_fields) - changed - {"phases"}
    assert {f: getattr(spec.spec, f) for f in same} == {f: getattr(base_spec.spec, f) for f in same}
