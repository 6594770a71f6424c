"""Dependencies point the right way: the numeric core imports without ROS or bag libraries, and no
module of the package imports itself through others (no cycles)."""

import ast
import subprocess
import sys
from pathlib import Path

import ship_ident

PACKAGE = Path(ship_ident.__file__).parent
# The doors onto the core: ROS, bags and files, the command line, benchmarks, demos.
DOORS = ("ros", "io", "commands", "cli", "errors", "bench", "threedof.data")
BLOCKED = ("rclpy", "rosbags", "mcap", "mcap_ros2")
BLOCKER = f"""
import sys
class Blocked:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in {BLOCKED!r}:
            raise ImportError(f"{{name}} is blocked: the numeric core must not need it")
        return None
sys.meta_path.insert(0, Blocked())
"""


def package_modules() -> list[str]:
    """Every module of ship_ident, dotted and relative to it (``estimators.base``), from the files."""
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if parts:
            names.append(".".join(parts))
    return names


def core_modules() -> list[str]:
    return [
        name for name in package_modules() if not any(name == door or name.startswith(door + ".") for door in DOORS)
    ]


def test_the_core_is_its_packages_and_the_doors_are_the_rest():
    """The core is the packages model, estimators, online, diagnosis and threedof's model; the doors
    (ros, io, commands, cli and its errors, bench) are everything that touches ROS, files or the screen."""
    core = set(core_modules())
    core_packages = {"model", "estimators", "online", "diagnosis", "threedof"}
    assert core_packages <= core
    assert {name.split(".")[0] for name in core} == core_packages
    assert not core & {"ros.node", "io.files", "io.fleet", "cli", "commands.replay", "bench.peers"}


def test_core_imports_with_ros_and_bag_libraries_blocked():
    imports = "".join(f"import ship_ident.{name}\n" for name in core_modules())
    check = f"for name in {BLOCKED!r}:\n    assert name not in sys.modules, name\n"
    process = subprocess.run(
        [sys.executable, "-c", BLOCKER + imports + check],
        capture_output=True,
        text=True,
        cwd=PACKAGE.parent,
        timeout=120,
    )
    assert process.returncode == 0, process.stderr.strip().splitlines()[-1:]


def test_the_blocker_blocks():
    process = subprocess.run(
        [sys.executable, "-c", BLOCKER + "import ship_ident.io.files\n"],
        capture_output=True,
        text=True,
        cwd=PACKAGE.parent,
        timeout=120,
    )
    assert process.returncode != 0 and "rosbags is blocked" in process.stderr


def imported_modules(name: str) -> set[str]:
    """The ship_ident modules that module ``name`` imports, at module level or inside functions."""
    path = PACKAGE.joinpath(*name.split(".")) if name else PACKAGE
    path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
    is_package = path.name == "__init__.py"
    modules = set(package_modules())
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = name.split(".") if name else []
                base = parts[: len(parts) - node.level + is_package] if node.level - is_package else parts
                stem = ".".join(base + (node.module.split(".") if node.module else []))
            else:
                stem = node.module or ""
                if not (stem == "ship_ident" or stem.startswith("ship_ident.")):
                    continue
                stem = stem[len("ship_ident.") :] if stem != "ship_ident" else ""
            candidates = [f"{stem}.{alias.name}" if stem else alias.name for alias in node.names]
            targets = ["ship_ident" + ("." + stem if stem else "")]
            targets += ["ship_ident." + c for c in candidates if c in modules]
        else:
            continue
        for target in targets:
            if target == "ship_ident" or target.startswith("ship_ident."):
                found.add(target[len("ship_ident.") :] if target != "ship_ident" else "")
    found.discard(name)
    return found


def import_cycle(graph: dict[str, set[str]]) -> list[str]:
    """One cycle of the directed graph as the list of its modules, or [] when there is none."""
    state, stack = {}, []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        state[node] = "done"
        stack.pop()
        return []

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return []


def test_the_graph_sees_relative_and_lazy_imports():
    assert {"online.config", "io.bag_replay", "online.samples"} <= imported_modules("io.fleet")
    assert "model.structure" in imported_modules("cli")  # imported inside main()
    assert "estimators.base" in imported_modules("estimators.prediction_error")
    assert import_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert import_cycle({"a": {"b"}, "b": set()}) == []


def test_the_identifier_knows_no_files_and_its_parts_not_the_identifier():
    """online.identifier is the identifier: its configuration, input checks, decisions on a window (the
    fit, the published uncertainty, the trust policy, the gain follow, their verdicts) and the estimate
    log (the node's file writer) are modules of their own, none of which needs the identifier."""
    decisions = {"online.window_fit", "online.uncertainty", "online.trust", "online.gain_follow", "online.verdicts"}
    assert {"online.config", "online.input_checks"} | decisions <= imported_modules("online.identifier")
    assert "online.estimate_log" not in imported_modules("online.identifier")
    for part in ("online.config", "online.input_checks", "online.estimate_log", *sorted(decisions)):
        assert "online.identifier" not in imported_modules(part), part
    assert "online.estimate_log" in imported_modules("ros.node")


def test_the_package_has_no_import_cycle():
    graph = {name: imported_modules(name) for name in package_modules() + [""]}
    assert import_cycle(graph) == []
