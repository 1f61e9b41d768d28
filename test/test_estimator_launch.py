"""launch/estimator.launch.py compiles and starts the right executable (launch itself is not installable here).

The checks read the file's syntax tree: the package, executable and node name it launches must
be the ones setup.py and the node declare, it takes the documented arguments, and it gives the
node the Fast DDS profile for raw HD images (itself checked here; test_estimator_load.py streams
through it).
"""
import ast
import re
from pathlib import Path
from xml.etree import ElementTree

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_FILE = ROOT / "launch" / "estimator.launch.py"


def tree() -> ast.Module:
    return ast.parse(compile(LAUNCH_FILE.read_text(), str(LAUNCH_FILE), "exec", flags=ast.PyCF_ONLY_AST))


def module_constants(module: ast.Module) -> dict[str, str]:
    return {target.id: node.value.value for node in module.body if isinstance(node, ast.Assign)
            and isinstance(node.value, ast.Constant) for target in node.targets if isinstance(target, ast.Name)}


def calls(module: ast.Module, name: str) -> list[ast.Call]:
    return [node for node in ast.walk(module) if isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name) and node.func.id == name]


def keyword(call: ast.Call, name: str, constants: dict[str, str]):
    value = next(k.value for k in call.keywords if k.arg == name)
    return constants[value.id] if isinstance(value, ast.Name) else ast.literal_eval(value)


def test_the_launch_file_starts_the_installed_estimator():
    module = tree()
    constants = module_constants(module)
    (node,) = calls(module, "Node")
    console_scripts = re.findall(r'"(\w+) = idpose_ros\.node\.process:main"', (ROOT / "setup.py").read_text())
    assert keyword(node, "package", constants) == "idpose_ros"
    assert [keyword(node, "executable", constants)] == console_scripts == ["estimator"]
    node_source = (ROOT / "idpose_ros" / "node" / "estimator_node.py").read_text()
    assert f'NODE_NAME = "{keyword(node, "name", constants)}"' in node_source
    assert any(isinstance(f, ast.FunctionDef) and f.name == "generate_launch_description" for f in module.body)


def test_the_launch_file_takes_the_documented_arguments_and_remaps_both_image_topics():
    module = tree()
    declared = [ast.literal_eval(call.args[0]) for call in calls(module, "DeclareLaunchArgument")]
    assert declared == ["params_file", "image_topic", "model_path"]
    (node,) = calls(module, "Node")
    remaps = next(k.value for k in node.keywords if k.arg == "remappings")
    assert [ast.literal_eval(pair.elts[0]) for pair in remaps.elts] == ["image", "image/compressed"]
    assert "estimator.yaml" in ast.unparse(module), "the default params file is the installed config"


@pytest.mark.slow  # starts a node or a process
def test_colcon_installs_the_launch_file(workspace):
    installed = workspace / "install" / "idpose_ros" / "share" / "idpose_ros" / "launch" / LAUNCH_FILE.name
    assert installed.read_text() == LAUNCH_FILE.read_text()


def test_the_node_gets_the_large_image_transport_profile_where_it_is_safe():
    module = tree()
    constants = module_constants(module)
    assert constants["PROFILE_VARIABLE"] == "FASTRTPS_DEFAULT_PROFILES_FILE"
    assert (ROOT / "config" / constants["LARGE_IMAGES_PROFILE"]).is_file()
    (node,) = calls(module, "Node")
    environment = next(k.value for k in node.keywords if k.arg == "additional_env")
    assert ast.unparse(environment) == "transport_environment(context)", "only the node's process, not the launch"
    (function,) = [f for f in module.body if isinstance(f, ast.FunctionDef) and f.name == "transport_environment"]
    guard = ast.unparse(function.body[1].test)
    assert "PROFILE_VARIABLE in os.environ" in guard, "a profile the user chose (even empty) wins"
    assert "RMW_IMPLEMENTATION" in guard and "rmw_fastrtps_cpp" in guard, "Fast DDS only"


def test_the_large_image_profile_enlarges_shared_memory_and_keeps_udp():
    profile = ElementTree.parse(ROOT / "config" / "fastdds_large_images.xml").getroot()
    namespace = {"dds": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    transports = {d.findtext("dds:transport_id", namespaces=namespace): d
                  for d in profile.iterfind(".//dds:transport_descriptor", namespace)}
    kinds = {d.findtext("dds:type", namespaces=namespace) for d in transports.values()}
    assert kinds == {"SHM", "UDPv4"}, "Fast DDS's two default transports: other hosts are still reached over UDP"
    (shm,) = [d for d in transports.values() if d.findtext("dds:type", namespaces=namespace) == "SHM"]
    assert int(shm.findtext("dds:segment_size", namespaces=namespace)) >= 5 * 1920 * 1080 * 3, "five 1080p frames"
    (participant,) = profile.iterfind("dds:participant", namespace)
    assert participant.get("is_default_profile") == "true"
    used = [t.text for t in participant.iterfind(".//dds:userTransports/dds:transport_id", namespace)]
    assert sorted(used) == sorted(transports)
    assert participant.findtext(".//dds:useBuiltinTransports", namespaces=namespace) == "false"


@pytest.mark.slow  # starts a node or a process
def test_colcon_installs_the_transport_profile(workspace):
    installed = workspace / "install" / "idpose_ros" / "share" / "idpose_ros" / "config" / "fastdds_large_images.xml"
    assert installed.read_text() == (ROOT / "config" / "fastdds_large_images.xml").read_text()
