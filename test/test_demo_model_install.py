"""colcon installs the embedded demo model's files with the package (package_data)."""
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # every test here starts a node or a process, or takes seconds

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ROOT / "idpose_core" / "assets" / "demo_model"


@pytest.mark.skipif(not (SHIPPED / "model.safetensors").is_file(), reason=f"no demo weights shipped in {SHIPPED}")
def test_colcon_installs_the_demo_model_assets(workspace):
    installed = list((workspace / "install" / "idpose_ros").glob(
        "lib/python3*/site-packages/idpose_core/assets/demo_model"))
    assert len(installed) == 1, installed
    shipped = sorted(p.name for p in SHIPPED.iterdir() if p.is_file())
    assert "model.safetensors" in shipped
    assert sorted(p.name for p in installed[0].iterdir() if p.is_file()) == shipped
    assert (installed[0] / "model.safetensors").stat().st_size == (SHIPPED / "model.safetensors").stat().st_size
