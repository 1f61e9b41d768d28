"""The code passes ruff with the repository's ruff.toml (pyflakes, pycodestyle, import order, bugbear, ...)."""
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

ROOT = Path(__file__).resolve().parents[1]


def ruff(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--config", str(ROOT / "ruff.toml"),
                           *args], capture_output=True, text=True, cwd=ROOT)


def test_the_repository_passes_ruff():
    result = ruff(".")
    assert result.returncode == 0, result.stdout + result.stderr


def test_ruff_flags_an_unused_import(tmp_path):
    sample = tmp_path / "sample.py"
    sample.write_text("import os\n")
    result = ruff(str(sample))
    assert result.returncode == 1 and "F401" in result.stdout
