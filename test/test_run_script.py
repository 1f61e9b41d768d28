"""`./run` installs once per set of inputs: the torch requirement (IDPOSE_TORCH), the requirement files, and
the interface package with the script that builds it."""
import os
import shutil
import subprocess
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

ROOT = Path(__file__).resolve().parents[1]
# What ./run reads to install: copied into a scratch checkout, so that a test may edit them.
INSTALL_INPUTS = ("run", "requirements.txt", "requirements-ros.txt", "requirements-test.txt",
                  "scripts/install_interfaces.py", "idpose_interfaces")


@pytest.fixture
def fake_venv(tmp_path):
    """A venv whose python records what ./run asks of it (in calls.txt) and does nothing."""
    venv, calls = tmp_path / "venv", tmp_path / "calls.txt"
    (venv / "bin").mkdir(parents=True)
    python = venv / "bin" / "python"
    python.write_text(f"#!/bin/sh\necho \"$*\" >> {calls}\n")
    python.chmod(0o755)

    def run(torch: str | None = None, checkout: Path = ROOT) -> list[str]:
        """``<checkout>/run test --co`` on the fake venv; the python calls it made."""
        calls.write_text("")
        env = {k: v for k, v in os.environ.items() if k != "IDPOSE_TORCH"} | {"IDPOSE_VENV": str(venv)}
        if torch:
            env["IDPOSE_TORCH"] = torch
        subprocess.run([str(checkout / "run"), "test", "--co"], env=env, check=True, capture_output=True)
        return calls.read_text().splitlines()

    return run


def test_a_changed_torch_requirement_reinstalls(fake_venv):
    first = fake_venv()
    assert "-m pip install --quiet torch==2.13.0" in first and first[-1] == "-m pytest --co"
    assert fake_venv() == ["-m pytest --co"]  # installed already: straight to the tests
    changed = fake_venv("torch==2.13.0+cu128")
    assert "-m pip install --quiet torch==2.13.0+cu128" in changed
    assert fake_venv("torch==2.13.0+cu128") == ["-m pytest --co"]


def test_an_install_takes_the_ros_wheels_then_builds_the_interfaces(fake_venv):
    calls = fake_venv()
    pip = "-m pip install --quiet --requirement=requirements.txt --requirement=requirements-ros.txt " \
          "--requirement=requirements-test.txt"
    assert calls.index(pip) < calls.index("scripts/install_interfaces.py") < calls.index("-m pytest --co")


def test_an_edited_interface_file_rebuilds_the_interfaces(fake_venv, tmp_path):
    checkout = tmp_path / "checkout"
    for name in INSTALL_INPUTS:
        source, copy = ROOT / name, checkout / name
        copy.parent.mkdir(parents=True, exist_ok=True)
        (shutil.copytree if source.is_dir() else shutil.copy2)(source, copy)
    assert "scripts/install_interfaces.py" in fake_venv(checkout=checkout)
    assert fake_venv(checkout=checkout) == ["-m pytest --co"]
    message = checkout / "idpose_interfaces" / "msg" / "ViewEstimate.msg"
    message.write_text(message.read_text() + "float32 new_field\n")
    assert "scripts/install_interfaces.py" in fake_venv(checkout=checkout)
    (checkout / "idpose_interfaces" / "msg" / "Extra.msg").write_text("int32 value\n")  # a new file counts too
    assert "scripts/install_interfaces.py" in fake_venv(checkout=checkout)
    assert fake_venv(checkout=checkout) == ["-m pytest --co"]
