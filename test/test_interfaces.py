"""idpose_interfaces as ./run installs it (scripts/install_interfaces.py): the types clients rely on, usable
with nothing set up, a real action round trip, and the build's fix-ups."""
import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from scripts import install_interfaces

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "idpose_interfaces"
# The names and types clients rely on; the files may add fields.
CONTRACT = {
    "ViewEstimate": {"header": "std_msgs/Header", "pose": "geometry_msgs/Pose", "confidence": "float",
                     "ambiguous": "boolean", "runner_up": "geometry_msgs/Pose", "roll_deg": "float",
                     "polar_deg": "float", "mask_method": "string", "polar_source": "string"},
    "Goal": {"images": "sequence<sensor_msgs/Image>", "preset": "string"},
    "Result": {"error_code": "uint8", "error_message": "string", "run_id": "uint32",
               "poses": "geometry_msgs/PoseArray", "views": "sequence<idpose_interfaces/ViewEstimate>",
               "object_distance": "double", "distance_source": "string"},
    "Feedback": {"stage": "string", "progress": "float", "forward_samples": "uint32", "seconds_elapsed": "float",
                 "seconds_remaining": "float"},
}
ERROR_CODES = {"SUCCEEDED": 0, "INVALID_GOAL": 1, "MODEL_UNAVAILABLE": 2, "FAILED": 3, "CANCELED": 4}
# Prints the installed types' fields and the result's constants named on the command line, as JSON.
DESCRIBE = """
import json
import sys
from idpose_interfaces.action import EstimatePoses
from idpose_interfaces.msg import ViewEstimate

types = {"ViewEstimate": ViewEstimate, "Goal": EstimatePoses.Goal, "Result": EstimatePoses.Result,
         "Feedback": EstimatePoses.Feedback}
print(json.dumps({"fields": {name: kind.get_fields_and_field_types() for name, kind in types.items()},
                  "codes": {name: getattr(EstimatePoses.Result, name) for name in sys.argv[1:]}}))
"""


def nothing_set_up() -> dict[str, str]:
    """A fresh shell's environment (no LD_LIBRARY_PATH, no setup script), with the tests' DDS isolation."""
    isolation = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
    return install_interfaces.clean_environment() | {name: os.environ[name] for name in isolation}


def run_clean(*args: str) -> str:
    result = subprocess.run([sys.executable, *args], env=nothing_set_up(), cwd="/", capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    return result.stdout


def source_fields(path: Path) -> list[list[str]]:
    """Field names of a .msg file, or of each part of a .action file (constants and comments left out)."""
    parts: list[list[str]] = [[]]
    for line in path.read_text().splitlines():
        words = line.split("#")[0].split()
        if words == ["---"]:
            parts.append([])
        elif len(words) >= 2 and "=" not in line.split("#")[0]:
            parts[-1].append(words[1])
    return parts


@pytest.fixture(scope="module")
def installed() -> dict:
    return json.loads(run_clean("-c", DESCRIBE, *ERROR_CODES))


@pytest.mark.slow  # starts a node or a process
def test_the_installed_types_carry_every_field_clients_rely_on(installed):
    for name, fields in CONTRACT.items():
        assert {field: installed["fields"][name].get(field) for field in fields} == fields, name
    assert installed["codes"] == ERROR_CODES


@pytest.mark.slow  # starts a node or a process
def test_the_installed_types_are_the_repository_s_files(installed):
    """A stale install (a .msg edited without ./run rebuilding) fails here."""
    (view,) = source_fields(PACKAGE / "msg" / "ViewEstimate.msg")
    goal, result, feedback = source_fields(PACKAGE / "action" / "EstimatePoses.action")
    for name, fields in {"ViewEstimate": view, "Goal": goal, "Result": result, "Feedback": feedback}.items():
        assert list(installed["fields"][name]) == fields, f"{name}: run ./run again to rebuild idpose_interfaces"


@pytest.mark.slow  # starts a node or a process
def test_a_goal_round_trips_between_an_action_client_and_server_with_nothing_set_up():
    out = json.loads(run_clean(str(ROOT / "test" / "estimate_poses_round_trip.py")).splitlines()[-1])
    assert out["error_code"] == 0 and out["run_id"] == 7
    assert out["frame"] == "camera_0" and out["poses_x"] == [0.0, 1.0]
    assert out["views"] == [["camera_0", 1.0, False, True, True], ["camera_1", 0.25, True, False, True]]
    expected = [["refinement", 0.333, 16, -1.0], ["refinement", 0.667, 32, 0.5], ["refinement", 1.0, 48, 0.0]]
    assert out["feedback"] and all(step in expected for step in out["feedback"])  # feedback is a topic: best effort
    assert out["feedback"] == sorted(out["feedback"], key=lambda step: step[1])


def test_the_cmake_exports_are_pointed_at_this_python_once(tmp_path):
    export = tmp_path / "share" / "std_msgs" / "cmake" / "export_std_msgs__rosidl_generator_pyExport.cmake"
    other = tmp_path / "share" / "std_msgs" / "cmake" / "std_msgsConfig.cmake"
    export.parent.mkdir(parents=True)
    export.write_text('INTERFACE_INCLUDE_DIRECTORIES "/opt/python/cp311-cp311/include/python3.11;'
                      '/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"\n')
    other.write_text("set(std_msgs_FOUND TRUE)\n")
    assert install_interfaces.fix_cmake_exports(tmp_path) == [export]
    paths = sysconfig.get_paths()
    assert export.read_text() == (f'INTERFACE_INCLUDE_DIRECTORIES "{paths["include"]};'
                                  f'{paths["platlib"]}/numpy/_core/include"\n')
    assert Path(paths["include"], "Python.h").is_file()
    assert install_interfaces.fix_cmake_exports(tmp_path) == []  # idempotent
    assert other.read_text() == "set(std_msgs_FOUND TRUE)\n"


def test_this_environment_s_exports_no_longer_name_the_build_machine():
    """./run fixed them: every export of the installed ROS wheels names include paths that exist here."""
    exports = list(Path(sys.prefix, "share").glob("*/cmake/*.cmake"))
    assert any("rosidl_generator_py" in path.name for path in exports)
    assert not [path for path in exports if install_interfaces.BUILD_PYTHON.search(path.read_text())]


def test_the_build_runs_on_this_python_and_links_the_extensions_to_lib(tmp_path):
    arguments = dict(argument[2:].split("=", 1) for argument in install_interfaces.cmake_arguments(tmp_path))
    assert arguments["Python3_EXECUTABLE"] == sys.executable
    site = Path(sysconfig.get_paths(vars={"base": str(tmp_path), "platbase": str(tmp_path)})["purelib"])
    origin, extensions = arguments["CMAKE_INSTALL_RPATH"].split(";")
    assert origin == "$ORIGIN"
    assert (site / "idpose_interfaces" / extensions.replace("$ORIGIN/", "")).resolve() == tmp_path / "lib"
    env = install_interfaces.build_environment(tmp_path, {"AMENT_PREFIX_PATH": "/opt/ros/jazzy", "PATH": "/usr/bin"})
    assert env["AMENT_PREFIX_PATH"] == f"{tmp_path}:/opt/ros/jazzy" and env["CMAKE_PREFIX_PATH"] == str(tmp_path)
    assert env["PATH"].split(":")[0] == str(Path(sys.executable).parent)


@pytest.mark.slow  # starts a node or a process
def test_a_broken_interface_file_fails_the_install_naming_it(tmp_path, monkeypatch):
    for name in ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH"):  # the ROS wheels found here, installed elsewhere
        monkeypatch.setenv(name, sys.prefix)
    package = tmp_path / "idpose_interfaces"
    shutil.copytree(PACKAGE, package)
    (package / "msg" / "ViewEstimate.msg").write_text("no_such_msgs/Thing thing\n")
    with pytest.raises(RuntimeError, match="`cmake .*` failed") as failure:
        install_interfaces.install(package, tmp_path / "prefix", tmp_path)
    assert "no_such_msgs" in str(failure.value)
    assert not (tmp_path / "prefix").exists()  # nothing installed
