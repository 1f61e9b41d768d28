"""docs/node.md's parameter table is exactly the node's declared parameters (`parameter_table()`): the same
names, and for each its ROS type, default, range or choices and read-only flag; the README's brief parameter
table names only declared parameters, with their defaults; the node page keeps its sections in order.

A parameter added to the code fails the first test until its row is in the table; the message gives the row.
"""
import json
import re
from pathlib import Path
from typing import Any

from idpose_ros.node.parameters import parameter_table

ROOT = Path(__file__).resolve().parents[1]
NODE_PAGE = ROOT / "docs" / "node.md"
FULL_TABLE = ("name", "type", "default", "range/choices", "meaning")
BRIEF_TABLE = ("parameter", "default", "meaning")
READ_ONLY = "**Read-only.**"
NODE_SECTIONS = ("Overview", "Topics", "Services", "Parameters", "Output frame", "Limits", "Walk-through")


def table_rows(path: Path, header: tuple[str, ...]) -> list[dict[str, str]]:
    """The rows of the Markdown table in ``path`` whose header row is ``header``, as {column: cell}."""
    lines = path.read_text().splitlines()
    header_line = "| " + " | ".join(header) + " |"
    assert header_line in lines, f"{path.relative_to(ROOT)} has no table with the header {header_line}"
    rows = []
    for line in lines[lines.index(header_line) + 2:]:
        if not line.startswith("|"):
            break
        rows.append(parse_row(line, header))
    return rows


def parse_row(line: str, header: tuple[str, ...]) -> dict[str, str]:
    """One Markdown table row as {column: cell} (an escaped \\| stays inside its cell)."""
    cells = [cell.strip() for cell in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
    assert len(cells) == len(header), f"row {line!r} has {len(cells)} cells, the table {len(header)}"
    return dict(zip(header, cells))


def code_span(cell: str) -> str:
    """The text of a cell that is one `code span`."""
    match = re.fullmatch(r"`([^`]*)`", cell)
    assert match, f"expected one `code span`, got {cell!r}"
    return match.group(1)


def ros_type(value: Any) -> str:
    """The ROS 2 parameter type a default declares: bool, integer, double, string, or an array of one."""
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "double"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list) and value:
        return ros_type(value[0]) + "[]"
    raise TypeError(f"no ROS parameter type for {value!r}")


def range_text(spec: dict[str, Any]) -> str:
    """The range/choices cell the code's spec calls for: `low .. high`, `a`, `b`, or empty."""
    def number(x: float) -> str:
        return str(int(x)) if float(x).is_integer() else repr(float(x))
    if spec["bounds"] is not None:
        return f"`{number(spec['bounds'][0])} .. {number(spec['bounds'][1])}`"
    return ", ".join(f"`{choice}`" for choice in spec["choices"])


def documented_range(cell: str) -> tuple[tuple[float, float] | None, tuple[str, ...]]:
    """(bounds, choices) a range/choices cell states."""
    bounds = re.fullmatch(r"`(-?[\d.e+]+) \.\. (-?[\d.e+]+)`", cell)
    if bounds:
        return (float(bounds.group(1)), float(bounds.group(2))), ()
    return None, tuple(re.findall(r"`([^`]*)`", cell))


def row_for(name: str, default: Any, spec: dict[str, Any]) -> str:
    """The table row the code calls for (its meaning is the description; say more in the doc as needed)."""
    meaning = spec["description"][0].upper() + spec["description"][1:] + "."
    if spec["read_only"]:
        meaning += f" {READ_ONLY}"
    return f"| `{name}` | {ros_type(default)} | `{json.dumps(default)}` | {range_text(spec)} | {meaning} |"


def differences(rows: list[dict[str, str]]) -> list[str]:
    """Every way the table differs from ``parameter_table()``, one line each, naming the parameter."""
    declared = {name: (default, spec) for name, default, spec in parameter_table()}
    documented: dict[str, dict[str, str]] = {}
    problems = []
    for row in rows:
        name = code_span(row["name"])
        if name in documented:
            problems.append(f"{name}: two rows in the table")
        documented[name] = row
    for name in documented.keys() - declared.keys():
        problems.append(f"{name}: in docs/node.md's table but not declared by parameter_table()")
    for name, (default, spec) in declared.items():
        if name not in documented:
            problems.append(f"{name}: declared in the code but not in docs/node.md's table; add the row\n    "
                            f"{row_for(name, default, spec)}")
            continue
        row = documented[name]
        if row["type"] != ros_type(default):
            problems.append(f"{name}: type: the table says {row['type']}, the code declares {ros_type(default)}")
        written = code_span(row["default"])
        try:
            value = json.loads(written)
        except json.JSONDecodeError:
            value = None
        if value != default or (value is not None and ros_type(value) != ros_type(default)):
            problems.append(f"{name}: default: the table says {written}, the code declares {json.dumps(default)}")
        bounds, choices = documented_range(row["range/choices"])
        expected_bounds = None if spec["bounds"] is None else tuple(float(b) for b in spec["bounds"])
        if (bounds, choices) != (expected_bounds, tuple(spec["choices"])):
            problems.append(f"{name}: range/choices: the table says {row['range/choices'] or '(nothing)'}, "
                            f"the code declares {range_text(spec) or '(nothing)'}")
        if (READ_ONLY in row["meaning"]) != spec["read_only"]:
            problems.append(f"{name}: the code declares it {'read-only' if spec['read_only'] else 'writable'}; "
                            f"its meaning should {'end with' if spec['read_only'] else 'not say'} {READ_ONLY}")
    return problems


def test_the_node_page_lists_exactly_the_declared_parameters():
    problems = differences(table_rows(NODE_PAGE, FULL_TABLE))
    assert not problems, "docs/node.md's parameter table differs from parameter_table():\n" + "\n".join(problems)


def test_the_comparison_names_what_differs():
    """The check itself, on the rows the code calls for: a missing row, a wrong default, a wrong range and a
    stray row are each named; the untouched rows pass."""
    rows = {name: parse_row(row_for(name, default, spec), FULL_TABLE) for name, default, spec in parameter_table()}
    assert differences(list(rows.values())) == []
    missing = rows.pop("max_views")
    rows["no_such_parameter"] = {**rows["seed"], "name": "`no_such_parameter`"}
    rows["object_distance"]["default"] = "`2.0`"
    rows["probe_batch"]["range/choices"] = "`1 .. 64`"
    problems = "\n".join(differences(list(rows.values())))
    assert "max_views: declared in the code but not in docs/node.md's table" in problems
    assert f"| `max_views` | {missing['type']} | {missing['default']} | {missing['range/choices']} |" in problems
    assert "no_such_parameter: in docs/node.md's table but not declared" in problems
    assert "object_distance: default: the table says 2.0, the code declares 1.0" in problems
    assert "probe_batch: range/choices: the table says `1 .. 64`, the code declares `1 .. 1024`" in problems


def test_the_readme_parameters_are_declared_with_their_defaults():
    declared = {name: default for name, default, _ in parameter_table()}
    rows = table_rows(ROOT / "README.md", BRIEF_TABLE)
    assert rows
    for row in rows:
        name = code_span(row["parameter"])
        assert name in declared, f"README.md's parameter table names {name}, which the node does not declare"
        assert json.loads(code_span(row["default"])) == declared[name], (
            f"README.md: {name}'s default is {code_span(row['default'])}, the code declares {declared[name]!r}")


def test_the_node_page_keeps_its_sections_in_order():
    headings = re.findall(r"^## (.+)$", NODE_PAGE.read_text(), flags=re.MULTILINE)
    found = [heading for heading in headings if heading in NODE_SECTIONS]
    assert found == list(NODE_SECTIONS), f"docs/node.md's sections: {headings}"
