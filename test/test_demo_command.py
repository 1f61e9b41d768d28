"""`./run demo` (idpose_ros.demo) runs evaluate_bag on the shipped bag and says which model it used."""
import json

import pytest

from idpose_core.demo_model.model import WEIGHTS_FILE
from idpose_core.demo_model.predictor import EMBEDDED_MODEL_DIR
from idpose_ros import demo


@pytest.mark.skipif((EMBEDDED_MODEL_DIR / WEIGHTS_FILE).is_file(), reason="embedded weights ship: covered by test_demo_model*")
def test_demo_without_embedded_weights_names_the_random_model(tmp_path, monkeypatch, capsys):
    """Reduced: 1 azimuth candidate, probe batch 1, no adjustment, 2 refinement steps, 32 px."""
    monkeypatch.chdir(tmp_path)
    code = demo.main(["--image-size", "32", "--solver-param", "azimuth_candidates=1",
                      "--solver-param", "adjust_steps=0", "--solver-param", "probe_batch=1",
                      "--solver-param", "refine_steps_per_view=2", "--solver-param", "runner_up_steps=0"])
    out = capsys.readouterr().out
    assert code == 0
    assert "RANDOM weights" in out and "| 2 |" in out
    report = json.loads((tmp_path / "demo_output" / "report.json").read_text())
    assert report["aggregates"]["2"]["pairs"] == 1
