"""launch/estimator.launch.py compiles and starts the right executable (launch itself is not installable here).

The checks read the file's syntax tree: the package, executable and node name it launches must
be the ones setup.py and the node declare, and it takes the documented arguments.
"""
import ast
import re
from pathlib import Path

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
    console_scripts = re.findall(r'"(\w+) = idpose_ros\.estimator_node:main"', (ROOT / "setup.py").read_text())
    assert keyword(node, "package", constants) == "idpose_ros"
    assert [keyword(node, "executable", constants)] == console_scripts == ["estimator"]
    node_source = (ROOT / "idpose_ros" / "estimator_node.py").read_text()
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


def test_colcon_installs_the_launch_file(workspace):
    installed = workspace / "install" / "idpose_ros" / "share" / "idpose_ros" / "launch" / LAUNCH_FILE.name
    assert installed.read_text() == LAUNCH_FILE.read_text()
