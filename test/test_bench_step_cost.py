"""bench/step_cost.py on the tiny architecture writes what unit_costs and the projections read.

Reduced: tiny Zero-1-to-3 config, 32 px, one alternation, one timed step; the figures themselves
mean nothing at this size, only their presence, consistency and the projection arithmetic do.
"""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from bench.step_cost import ADJUSTED_CANDIDATES
from bench.unit_costs import QUIET_REFERENCE, UnitCosts, all_costs

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("step_cost") / "step_cost.json"
    subprocess.run([sys.executable, "bench/step_cost.py", "--config", "tiny", "--size", "32", "--alternations", "1",
                    "--repeats", "1", "--threads", "1", "--out", str(out)], cwd=ROOT, check=True, capture_output=True)
    return out


def test_every_kind_is_measured_in_every_precision(tiny_run):
    report = json.loads(tiny_run.read_text())
    assert set(report["median"]) == {"official_step", "official_probe"} | {
        f"{kind}@{precision}" for kind in ("ours_step", "ours_adjust", "ours_probe")
        for precision in ("float32", "bfloat16")}
    for figures in report["median"].values():
        assert figures["seconds"] > 0 and figures["cpu_seconds"] > 0
        assert 0 < figures["run_peak_gb"] <= figures["peak_gb"]
    for precision in ("float32", "bfloat16"):
        adjust = report["median"][f"ours_adjust@{precision}"]
        # one adjust step differentiates the better half of the grid: per sample is the step's time over that
        assert adjust["per_sample_seconds"] == pytest.approx(adjust["seconds"] / ADJUSTED_CANDIDATES, rel=1e-6)
        assert report["ratio_official_over_ours"][precision]["step_seconds"] == pytest.approx(
            report["median"]["official_step"]["seconds"] / report["median"][f"ours_step@{precision}"]["seconds"])


def test_projection_charges_each_kind_of_sample_its_own_unit(tiny_run):
    costs = UnitCosts.load(tiny_run, "seconds", "bfloat16")
    views, forward, backward, adjust = 2, 1000, 300, 200
    expected = (views * costs.encode_per_view + adjust * costs.ours_adjust_sample + 100 * costs.ours_step
                + 700 * costs.ours_probe / costs.probe_samples)
    assert costs.probe_samples == json.loads(tiny_run.read_text())["setup"]["probe_batch"]
    assert costs.ours_seconds(views, forward, backward, adjust) == pytest.approx(expected)
    assert costs.official_seconds(3, 4) == pytest.approx(3 * costs.official_probe + 4 * costs.official_step)


def test_all_costs_gives_wall_cpu_and_reference_units_per_precision(tiny_run):
    costs = all_costs(["float32", "bfloat16"], tiny_run)
    assert set(costs) == {"float32", "bfloat16"}
    for units in costs.values():
        assert set(units) == {"seconds", "cpu_seconds", "reference_seconds"}
    # the reference float32 step is the quiet reference figure; bfloat16 keeps its measured ratio to it
    reference, cpu = costs["bfloat16"]["reference_seconds"], costs["bfloat16"]["cpu_seconds"]
    quiet_step = QUIET_REFERENCE["ours_step"]
    assert costs["float32"]["reference_seconds"].ours_step == pytest.approx(quiet_step)
    assert reference.ours_step / quiet_step == pytest.approx(cpu.ours_step / costs["float32"]["cpu_seconds"].ours_step)


def test_a_precision_the_run_did_not_measure_is_named(tiny_run):
    with pytest.raises(KeyError, match="float16"):
        UnitCosts.load(tiny_run, "seconds", "float16")
