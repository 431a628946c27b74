"""Every shipped YAML validates (the benchmarks' configs too: a broken one would otherwise
surface only hours into a benchmark), and `validate` / `tasks` summarise them."""

from __future__ import annotations

import pytest

from taskforge.cli import main
from tests.conftest import ROOT

SHIPPED = sorted(
    str(p.relative_to(ROOT)) for folder in ("tasks", "agents", "curricula", "benchmarks/configs")
    for p in (ROOT / folder).rglob("*.yaml")
)


@pytest.mark.parametrize("relpath", SHIPPED)
def test_shipped_file_validates(relpath, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert main(["validate", relpath]) == 0
    out = capsys.readouterr()
    assert f"{relpath}: ok" in out.out
    assert out.err == ""


def test_pick_place_summary_names_every_stage_term_and_range(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert main(["validate", "tasks/metaworld/pick_place.yaml"]) == 0
    out = capsys.readouterr().out
    for text in ("backend metaworld", "pick-place-v3", "1. reach", "2. push", "3. pick", "4. place",
                 "+1*tcp_to_object", "object_to_goal_distance < 0.07", "body_mass: scale by uniform[0.5, 1.5]",
                 "dof_damping: scale by loguniform[0.3, 3]", "gravity: add by N(0, 0.4)", "goals hidden", "test (held out) 50"):
        assert text in out, text
    assert "object start" not in out  # ML1's own placement: nothing to say
    assert main(["validate", "tasks/metaworld/reach.yaml"]) == 0
    assert "object start: random per task instance" in capsys.readouterr().out


def test_tasks_lists_shipped_tasks_with_stages(capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    assert main(["tasks"]) == 0
    out = capsys.readouterr().out
    assert "tasks/metaworld/pick_place.yaml" in out
    assert "reach -> push -> pick -> place" in out
    assert "mt10" in out


def test_pick_place_task_has_the_four_stages_in_order():
    from taskforge import load_task

    task = load_task(ROOT / "tasks/metaworld/pick_place.yaml")
    assert task.stage_names == ["reach", "push", "pick", "place"]
