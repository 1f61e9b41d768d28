"""`./run demo` (idpose_ros.demo) evaluates every shipped demo bag with the embedded model and sums up."""
import json
import math

import pytest

from idpose_ros import demo

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

REDUCED = ["--image-size", "64", "--solver-param", "azimuth_candidates=2", "--solver-param", "adjust_steps=0",
           "--solver-param", "probe_batch=1", "--solver-param", "refine_steps_per_view=2",
           "--solver-param", "runner_up_steps=0"]


def test_demo_evaluates_each_demo_object_with_the_embedded_model(tmp_path, monkeypatch, capsys):
    """Reduced solver (2 azimuth candidates, probe batch 1, 2 refinement steps, 64 px): the wiring, not accuracy."""
    monkeypatch.chdir(tmp_path)
    assert demo.main(REDUCED) == 0
    out = capsys.readouterr().out
    names = [bag.name for bag in demo.demo_bags()]
    assert names == ["desk", "duck", "lego", "mug", "soccerball", "teddy"]
    summary = out.split("All demo objects")[1]
    for name in names:
        report = json.loads((tmp_path / "demo_output" / name / "report.json").read_text())
        assert report["model"]["model_path"] == "" and report["aggregates"]["2"]["pairs"] == 1
        assert f"| {name} | 1 |" in summary
    assert "| all | 6 |" in summary.split("never saw")[0]
    novel = [bag.name for bag in demo.novel_demo_bags()]
    assert novel == ["blob_880", "toy_heldout_0080"]
    unseen = out.split("Objects the embedded model never saw")[1].split("on a tabletop")[0]
    for name in novel:
        assert f"| {name} | 1 |" in unseen
    robot_bag = "toy_heldout_0080_tabletop"
    assert [bag.name for bag in demo.robot_demo_bags()] == [robot_bag]
    posed, alone = (json.loads((tmp_path / "demo_output" / folder / robot_bag / "report.json").read_text())
                    for folder in (".", "diffusion_only"))
    for report in (posed, alone):
        assert report["aggregates"]["2"]["pairs"] == 1
        details = report["estimates"][0]["details"]
        assert details["distance_source"] == "depth" and details["polar_source"] == "gravity", "the inputs are read"
    margins = [[view["refinement"]["margin"] for view in report["estimates"][0]["details"]["views"][1:]]
               for report in (posed, alone)]
    assert all(math.isfinite(m) for m in margins[0]) and all(math.isnan(m) for m in margins[1]), "verifier, then not"
    tabletop, diffusion_only = out.split("on a tabletop")[1].split("the diffusion estimate alone")
    assert f"| {robot_bag} | 1 |" in tabletop and f"| {robot_bag} | 1 |" in diffusion_only
