"""What a ROS 2 user's tools read: package.xml declares every ROS package imported, the launch file
parses and names the shipped parameter file. (``launch`` is not on the package index: the launch
file cannot run here; its installation is checked by the colcon build, test_colcon.py.)"""

import ast
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import ship_ident

ROOT = Path(__file__).resolve().parent.parent
LAUNCH_FILE = ROOT / "launch" / "ship_ident.launch.py"
# The ROS packages installed beside the venv (the rclpy wheels register theirs in the ament index).
AMENT_PACKAGES = Path(sys.prefix) / "share" / "ament_index" / "resource_index" / "packages"
LAUNCH_PACKAGES = {"launch", "launch_ros"}  # ROS packages, not on the package index: not in the index here


def top_level_imports(path: Path) -> set[str]:
    """The first component of every absolute import of a Python file (module level or inside functions)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names.add(node.module.split(".")[0])
    return names


def exec_depends() -> set[str]:
    return {e.text for e in ElementTree.parse(ROOT / "package.xml").getroot().iter("exec_depend")}


def test_package_xml_declares_every_ros_package_imported_and_no_other():
    assert AMENT_PACKAGES.is_dir(), AMENT_PACKAGES
    ros = {p.name for p in AMENT_PACKAGES.iterdir()} | LAUNCH_PACKAGES
    sources = sorted(Path(ship_ident.__file__).parent.rglob("*.py")) + [LAUNCH_FILE]
    imported = set().union(*(top_level_imports(path) for path in sources)) & ros
    assert {"rclpy", "rcl_interfaces", "std_msgs", "geometry_msgs", "launch_ros"} <= imported
    declared = exec_depends()
    assert imported - declared == set(), "imported, not in package.xml"
    assert {d for d in declared if not d.startswith("python3-")} - imported == set(), "declared, never imported"


def test_launch_file_parses_and_names_the_shipped_parameter_file():
    tree = ast.parse(LAUNCH_FILE.read_text())
    functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert "generate_launch_description" in functions
    (parameter_file,) = [
        ast.literal_eval(node.value)
        for node in tree.body
        if isinstance(node, ast.Assign) and [t.id for t in node.targets] == ["PARAMETER_FILE"]
    ]
    assert (ROOT.joinpath(*parameter_file)).is_file()
    arguments = {
        node.args[0].value
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "DeclareLaunchArgument"
    }
    assert arguments == {"params_file", "namespace", "use_sim_time"}
