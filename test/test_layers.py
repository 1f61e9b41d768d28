"""The three layers stay apart: idpose_core never imports ROS, msg_adapters never imports torch."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FORBIDDEN = {
    "idpose_core": ("rclpy", "msg_adapters", "idpose_ros", "rosbags", "ament_index_python"),
    "msg_adapters": ("torch", "idpose_core", "diffusers", "transformers", "idpose_ros"),
}


def imported_modules(path: Path) -> list[str]:
    """Top-level module names of every import statement in a Python file (at any depth)."""
    names = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names += [alias.name.split(".")[0] for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.append(node.module.split(".")[0])
    return names


def is_forbidden(package: str, module: str) -> bool:
    """ROS message packages are forbidden in idpose_core only; msg_adapters exists to use them."""
    ros_messages = package == "idpose_core" and module.endswith(("_msgs", "_srvs"))
    return module in FORBIDDEN[package] or ros_messages


def violations(package: str) -> list[str]:
    return [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in sorted((ROOT / package).rglob("*.py"))
        for name in imported_modules(path)
        if is_forbidden(package, name)
    ]


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_layer_imports(package):
    assert (ROOT / package / "__init__.py").exists()
    assert violations(package) == []


def test_checker_catches_a_violation(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("import os\nfrom sensor_msgs.msg import Image\n\ndef f():\n    import rclpy\n")
    assert imported_modules(bad) == ["os", "sensor_msgs", "rclpy"]
    assert [m for m in imported_modules(bad) if is_forbidden("idpose_core", m)] == ["sensor_msgs", "rclpy"]
    assert not is_forbidden("msg_adapters", "sensor_msgs")
