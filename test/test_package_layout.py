"""The repository's two packages build with colcon (ament_python and ament_cmake) and install what `ros2 run`
needs; the license and changelog agree with their package.xml files."""
import os
import subprocess
import sys
from pathlib import Path

import pytest
from catkin_pkg.changelog import get_changelog_from_path
from catkin_pkg.package import parse_package

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow  # starts a node or a process
def test_colcon_sees_an_ament_python_package(tmp_path, colcon):
    listing = colcon("list", "--base-paths", str(ROOT), cwd=tmp_path)
    assert "idpose_ros" in listing and "(ros.ament_python)" in listing


@pytest.mark.slow  # starts a node or a process
def test_ros2_run_finds_the_estimator(workspace):
    """What `ros2 run idpose_ros estimator` does: ament index -> prefix -> lib/idpose_ros/estimator."""
    script = (
        f". {workspace / 'install' / 'setup.sh'} && {sys.executable} -c "
        "'from ament_index_python.packages import get_package_prefix, get_package_share_directory;"
        "print(get_package_prefix(\"idpose_ros\")); print(get_package_share_directory(\"idpose_ros\"))'"
    )
    out = subprocess.run(["bash", "-c", script], capture_output=True, text=True, check=True).stdout.split()
    prefix, share = Path(out[0]), Path(out[1])
    assert prefix == workspace / "install" / "idpose_ros"
    executable = prefix / "lib" / "idpose_ros" / "estimator"
    assert executable.is_file() and os.access(executable, os.X_OK)
    assert (share / "package.xml").is_file()
    assert sorted(p.name for p in (share / "config").glob("*.yaml")) == sorted(
        p.name for p in (ROOT / "config").glob("*.yaml"))


@pytest.mark.slow  # starts a node or a process
def test_colcon_sees_both_packages_and_builds_the_interfaces_first(tmp_path, colcon):
    listing = colcon("list", "--topological-order", "--base-paths", str(ROOT), str(ROOT / "idpose_interfaces"),
                     cwd=tmp_path)
    assert [(row.split("\t")[0], row.split("\t")[2]) for row in listing.splitlines()] == [
        ("idpose_interfaces", "(ros.ament_cmake)"), ("idpose_ros", "(ros.ament_python)")]


@pytest.mark.slow  # starts a node or a process
def test_the_workspace_command_builds_both_packages(workspace):
    """The command docs/building.md gives, as the workspace fixture ran it; the types come from the workspace."""
    command = next(line for line in (workspace / "log" / "latest_build" / "logger_all.log").read_text().splitlines()
                   if "Command line arguments" in line)
    assert "'--base-paths', 'src', 'src/idpose_ros/idpose_interfaces'" in command
    documented = (ROOT / "docs" / "building.md").read_text()
    assert "colcon build --base-paths src src/idpose_ros/idpose_interfaces" in documented
    script = (
        f". {workspace / 'install' / 'setup.sh'} && {sys.executable} -c "
        "'from ament_index_python.packages import get_package_prefix; import idpose_interfaces.msg as m;"
        "from idpose_interfaces.action import EstimatePoses; EstimatePoses.Goal(images=[]);"
        "print(get_package_prefix(\"idpose_interfaces\")); print(m.__file__)'"
    )
    out = subprocess.run(["bash", "-c", script], capture_output=True, text=True, check=True).stdout.split()
    prefix = workspace / "install" / "idpose_interfaces"
    assert Path(out[0]) == prefix and Path(out[1]).is_relative_to(prefix)
    assert sorted(p.name for p in (prefix / "share" / "idpose_interfaces" / "action").glob("*.action")) == [
        "EstimatePoses.action"]


def test_the_license_and_the_changelog_agree_with_both_package_xml_files():
    packages = [parse_package(str(folder / "package.xml")) for folder in (ROOT, ROOT / "idpose_interfaces")]
    assert {license for package in packages for license in package.licenses} == {"MIT"}
    assert len({package.version for package in packages}) == 1
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "idpose_ros developers" in text
    changelog = get_changelog_from_path(str(ROOT / "CHANGELOG.rst"), "idpose_ros")
    assert next(version for version, _, _ in changelog.foreach_version()) == packages[0].version
    text = (ROOT / "CHANGELOG.rst").read_text()
    forthcoming = text.split("Forthcoming\n-----------\n")[1].split(f"\n{packages[0].version} (")[0]
    assert "idpose_interfaces" in forthcoming
