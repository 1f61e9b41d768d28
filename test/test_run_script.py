"""`./run` installs once per set of requirements, the torch requirement included (IDPOSE_TORCH)."""
import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_a_changed_torch_requirement_reinstalls(tmp_path):
    venv, calls = tmp_path / "venv", tmp_path / "calls.txt"
    (venv / "bin").mkdir(parents=True)
    python = venv / "bin" / "python"  # records what ./run asks of the venv's python
    python.write_text(f"#!/bin/sh\necho \"$*\" >> {calls}\n")
    python.chmod(0o755)

    def run(torch: str | None) -> list[str]:
        calls.write_text("")
        env = {k: v for k, v in os.environ.items() if k != "IDPOSE_TORCH"} | {"IDPOSE_VENV": str(venv)}
        if torch:
            env["IDPOSE_TORCH"] = torch
        subprocess.run([str(ROOT / "run"), "test", "--co"], env=env, check=True, capture_output=True)
        return calls.read_text().splitlines()

    first = run(None)
    assert "-m pip install --quiet torch==2.13.0" in first and first[-1] == "-m pytest --co"
    assert run(None) == ["-m pytest --co"]  # installed already: straight to the tests
    changed = run("torch==2.13.0+cu128")
    assert "-m pip install --quiet torch==2.13.0+cu128" in changed
    assert run("torch==2.13.0+cu128") == ["-m pytest --co"]
