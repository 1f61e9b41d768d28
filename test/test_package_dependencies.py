"""package.xml declares what the code imports, under names `rosdep install` resolves.

Each dependency must be a ROS 2 Jazzy package or a rosdep key, from lists checked against
ros/rosdistro (jazzy/distribution.yaml, rosdep/base.yaml, rosdep/python.yaml at commit 8468e88,
2026-08-22); a key outside them (e.g. the non-existent ``python3-torch-pip``) makes `rosdep install`
fail for every user. Libraries without a key are installed from requirements.txt. A workspace package
(idpose_interfaces, beside the Python package) counts when its folder in this repository defines it.
"""
import ast
import sys
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

ROOT = Path(__file__).resolve().parents[1]
CODE = ("idpose_core", "idpose_ros", "msg_adapters", "launch")
# Released Jazzy packages, by the rosdistro repository that releases them.
ROS_PACKAGES = {
    "rclpy": "rclpy", "rcl_interfaces": "rcl_interfaces", "builtin_interfaces": "rcl_interfaces",
    "std_msgs": "common_interfaces", "std_srvs": "common_interfaces", "sensor_msgs": "common_interfaces",
    "geometry_msgs": "common_interfaces", "visualization_msgs": "common_interfaces",
    "diagnostic_msgs": "common_interfaces", "ament_index_python": "ament_index", "launch": "launch",
    "launch_ros": "launch_ros", "action_msgs": "rcl_interfaces", "ament_cmake": "ament_cmake",
    "rosidl_default_generators": "rosidl_defaults", "rosidl_default_runtime": "rosidl_defaults",
    "lifecycle_msgs": "rcl_interfaces", "tf2_ros": "geometry2",
}
# Packages of this repository, built in the same workspace: name -> folder.
WORKSPACE_PACKAGES = {"idpose_interfaces": ROOT / "idpose_interfaces"}
# rosdep keys, by the rosdistro file that defines them.
ROSDEP_KEYS = {
    "python3-numpy": "python.yaml", "python3-opencv": "python.yaml", "python3-tqdm": "python.yaml",
    "python3-matplotlib": "python.yaml", "python3-torch": "python.yaml", "python3-transformers-pip": "python.yaml",
    "python3-rosbags-pip": "python.yaml", "python3-pybullet-pip": "python.yaml", "python3-pytest": "python.yaml",
    "python3-hypothesis": "python.yaml", "python3-yaml": "python.yaml", "python3-ruff-pip": "python.yaml",
    "python3-scipy": "python.yaml",
}
# Imported module -> the dependency that provides it (None: no rosdep key, installed from requirements.txt).
PROVIDED_BY = {
    "numpy": "python3-numpy", "scipy": "python3-scipy", "cv2": "python3-opencv", "tqdm": "python3-tqdm",
    "matplotlib": "python3-matplotlib",
    "torch": "python3-torch", "transformers": "python3-transformers-pip", "rosbags": "python3-rosbags-pip",
    "pybullet": "python3-pybullet-pip", "pybullet_data": "python3-pybullet-pip", "diffusers": None,
    "safetensors": None, "ray": None, "pycolmap": None, "mcap": None, "small_gicp": None, "kiss_matcher": None,
    "plyfile": None,
    **{name: name for name in [*ROS_PACKAGES, *WORKSPACE_PACKAGES]},
}
REQUIREMENT_OF = {"diffusers": "diffusers", "safetensors": "safetensors", "ray": "ray", "pycolmap": "pycolmap",
                  "mcap": "mcap", "small_gicp": "small-gicp", "kiss_matcher": "kiss-matcher", "plyfile": "plyfile"}
OWN = {"idpose_core", "idpose_ros", "msg_adapters"}


@pytest.fixture(scope="module")
def package():
    return parse_package(str(ROOT / "package.xml"))


def imported_modules() -> set[str]:
    """Top-level names of every absolute import in the installed code."""
    names = set()
    for folder in CODE:
        for file in (ROOT / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(file.read_text(), str(file))):
                if isinstance(node, ast.Import):
                    names.update(alias.name.split(".")[0] for alias in node.names)
                elif isinstance(node, ast.ImportFrom) and node.level == 0:
                    names.add(node.module.split(".")[0])
    return names - OWN - set(sys.stdlib_module_names)


def declared(package) -> list[str]:
    return [d.name for d in package.exec_depends + package.test_depends + package.build_depends
            + package.buildtool_depends]


def test_every_dependency_is_a_released_package_a_rosdep_key_or_a_workspace_package(package):
    unknown = [name for name in declared(package)
               if name not in ROS_PACKAGES and name not in ROSDEP_KEYS and name not in WORKSPACE_PACKAGES]
    assert not unknown, f"not a Jazzy package, a checked rosdep key nor a package of this repository: {unknown}"


@pytest.mark.parametrize("name", sorted(WORKSPACE_PACKAGES))
def test_a_workspace_dependency_is_defined_in_this_repository(package, name):
    assert name in declared(package)
    assert parse_package(str(WORKSPACE_PACKAGES[name] / "package.xml")).name == name


def test_the_interface_package_depends_on_released_packages_and_every_package_its_types_use():
    interfaces = parse_package(str(WORKSPACE_PACKAGES["idpose_interfaces"] / "package.xml"))
    unknown = [name for name in declared(interfaces) if name not in ROS_PACKAGES]
    assert not unknown, f"not a Jazzy package: {unknown}"
    used = set()  # packages named by field types, e.g. geometry_msgs in `geometry_msgs/Pose pose`
    for path in [*WORKSPACE_PACKAGES["idpose_interfaces"].glob("msg/*.msg"),
                 *WORKSPACE_PACKAGES["idpose_interfaces"].glob("action/*.action")]:
        for line in path.read_text().splitlines():
            field_type = line.split("#")[0].split()[:1]
            if field_type and "/" in field_type[0]:
                used.add(field_type[0].split("/")[0])
    assert used == {"std_msgs", "geometry_msgs", "sensor_msgs"}
    depends = {d.name for d in interfaces.build_depends} & {d.name for d in interfaces.exec_depends}
    assert used <= depends, f"types from {sorted(used - depends)} need <depend> in idpose_interfaces/package.xml"
    assert "rosidl_interface_packages" in [group.name for group in interfaces.member_of_groups]


def test_requirements_txt_has_no_ros_package():
    ros = [line for line in (ROOT / "requirements.txt").read_text().splitlines() if line.startswith("ros-")]
    assert not ros, f"ROS packages come from the ROS installation in a workspace: {ros}"


def test_every_third_party_import_is_declared_or_pip_installed(package):
    runtime = {d.name for d in package.exec_depends}
    requirements = (ROOT / "requirements.txt").read_text()
    for module in sorted(imported_modules()):
        assert module in PROVIDED_BY, f"{module} is imported but no dependency is known to provide it"
        key = PROVIDED_BY[module]
        if key is None:
            assert f"\n{REQUIREMENT_OF[module]}==" in requirements, f"{module} has no rosdep key and no pinned pip line"
        else:
            assert key in runtime, f"{module} is imported: package.xml needs <exec_depend>{key}</exec_depend>"


def test_the_import_scan_sees_the_known_imports():
    assert {"torch", "rclpy", "launch_ros", "cv2", "diffusers"} <= imported_modules()
