"""The structure rules: command-line modules are leaves, and no module imports itself back through others.

A command-line module is one that setup.py installs as a console script or that runs as ``__main__``.
No module outside test/ may import one (the node's process entry, ``idpose_ros.node.process``, is one; the
node class a replay client starts in its process lives elsewhere). No import cycle, TYPE_CHECKING-guarded or
not, among the three packages. The graph is read from the source (every ``import`` statement, at any depth),
so the rules hold for what is written, not for what happens to run.
"""
import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("idpose_core", "msg_adapters", "idpose_ros")
IMPORTERS = ("bench", "scripts", "examples")  # code outside the packages that must not import a CLI either


def module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def package_modules(root: Path) -> dict[str, Path]:
    return {module_name(path, root): path for package in PACKAGES for path in sorted((root / package).rglob("*.py"))}


def imports_of(path: Path, name: str, modules: dict[str, Path]) -> set[str]:
    """The package modules ``path`` (module ``name``, or None outside the packages) imports, resolved to files."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]

    def resolve(target: str) -> str | None:
        while target and target not in modules:
            target = target.rpartition(".")[0]
        return target or None

    found = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            targets = [base, *(f"{base}.{alias.name}" for alias in node.names)]
        found |= {resolved for target in targets if (resolved := resolve(target)) and resolved != name}
    return found


def import_graph(root: Path) -> dict[str, set[str]]:
    modules = package_modules(root)
    return {name: imports_of(path, name, modules) for name, path in modules.items()}


def command_line_modules(root: Path) -> set[str]:
    scripts = set(re.findall(r"=\s*([\w.]+):\w+", (root / "setup.py").read_text()))
    mains = {name for name, path in package_modules(root).items() if '__name__ == "__main__"' in path.read_text()}
    return scripts | mains


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected groups of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    groups: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for other in graph.get(node, ()):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            group = []
            while True:
                member = stack.pop()
                group.append(member)
                if member == node:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return groups


def cli_imports(root: Path) -> list[str]:
    """Every import of a command-line module by package code (other than itself) or by bench/scripts/examples."""
    modules, clis = package_modules(root), command_line_modules(root)
    found = [f"{name} imports {target}" for name, targets in import_graph(root).items() for target in targets
             if target in clis]
    for folder in IMPORTERS:
        for path in sorted((root / folder).rglob("*.py")) if (root / folder).is_dir() else ():
            found += [f"{path.relative_to(root)} imports {target}"
                      for target in imports_of(path, "", modules) if target in clis]
    return found


def test_command_line_modules_are_leaves():
    clis = command_line_modules(ROOT)
    assert {"idpose_ros.evaluate_bag", "idpose_ros.evaluate_dataset", "idpose_ros.demo",
            "idpose_ros.make_synthetic_bag"} <= clis
    assert cli_imports(ROOT) == []


def test_no_import_cycle():
    assert cycles(import_graph(ROOT)) == []


def test_the_checks_catch_a_cycle_and_an_imported_command_line_module(tmp_path):
    """A tree with a TYPE_CHECKING-guarded cycle and a library importing a CLI module fails both checks."""
    for package in PACKAGES:
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text("")
    (tmp_path / "setup.py").write_text('entry_points={"console_scripts": ["tool = idpose_ros.tool:main"]}\n')
    (tmp_path / "idpose_ros" / "tool.py").write_text("def main():\n    pass\n")
    (tmp_path / "idpose_ros" / "library.py").write_text("from idpose_ros.tool import main\n")
    (tmp_path / "idpose_core" / "a.py").write_text("from idpose_core import b\n")
    (tmp_path / "idpose_core" / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from idpose_core.a import thing\n")
    assert cycles(import_graph(tmp_path)) == [["idpose_core.a", "idpose_core.b"]]
    assert cli_imports(tmp_path) == ["idpose_ros.library imports idpose_ros.tool"]
