"""bench/gpu_check.py in its reduced mode on the CPU: every figure it promises is there and consistent.

Reduced: tiny architecture, 64 px, two precisions (float32 first: the estimates run in it, four times faster than
bfloat16 on a CPU), schedules cut to a few samples per stage; the figures themselves mean nothing at this size (on
a GPU the script runs the full-size model).
"""
import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("gpu_check") / "gpu_check.json"
    subprocess.run([sys.executable, "bench/gpu_check.py", "--reduced", "--device", "cpu", "--threads", "1",
                    "--repeats", "1", "--precisions", "float32", "bfloat16", "--out", str(out)],
                   cwd=ROOT, check=True, capture_output=True)
    return json.loads(out.read_text())


def test_step_and_probe_cost_and_memory_per_precision(report):
    assert set(report["precisions"]) == {"bfloat16", "float32"}
    for costs in report["precisions"].values():
        for kind in ("step", "step_with_cancel_hooks", "probe"):
            assert costs[kind]["seconds"] > 0 and costs[kind]["peak_gb"] > 0
    for precision, ratio in report["step_ratio_official_over_ours"].items():
        assert ratio == pytest.approx(report["official_step_float32"]["seconds"]
                                      / report["precisions"][precision]["step"]["seconds"])


def test_one_estimate_per_preset_with_its_sample_counts(report):
    assert set(report["estimates"]) == {"default", "fast", "live", "ifusion"}
    for row in report["estimates"].values():
        assert 0 < row["backward_samples"] < row["forward_samples"] and row["seconds"] > 0
    # live is timed on its own case, the elevation known, so it searches the azimuth and never falls back
    assert [name for name, row in report["estimates"].items() if row["elevation_known"]] == ["live"]
    assert report["estimates"]["live"]["forward_samples"] < report["estimates"]["fast"]["forward_samples"]
    # the reduced ifusion search: 4 starts x 2 directions x 2 steps differentiated, nothing else
    assert report["estimates"]["ifusion"]["backward_samples"] == 16


def test_an_absent_device_is_one_line():
    if __import__("torch").cuda.is_available():
        pytest.skip("a CUDA device is visible here")
    done = subprocess.run([sys.executable, "bench/gpu_check.py", "--reduced", "--device", "cuda"], cwd=ROOT,
                          capture_output=True, text=True)
    assert done.returncode == 2 and "device 'cuda' is not available" in done.stderr and "Traceback" not in done.stderr
