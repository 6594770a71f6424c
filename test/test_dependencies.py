"""Dependencies point the right way: the numeric core imports without ROS or bag libraries."""
import subprocess
import sys
from pathlib import Path

import ship_ident

PACKAGE = Path(ship_ident.__file__).parent
# The doors onto the core: ROS, bags and files, the command line, benchmarks, demos.
DOORS = ("node", "io", "commands", "cli", "demo", "fleet", "bag_replay", "bench", "threedof.data")
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
    return [name for name in package_modules()
            if not any(name == door or name.startswith(door + ".") for door in DOORS)]


def test_the_core_is_every_module_but_the_doors():
    core = set(core_modules())
    assert {"dataset", "signals", "structure", "effects", "integrate", "estimators", "simulator", "metrics",
            "innovations", "change", "diagnose", "online", "report", "samples", "threedof"} <= core
    assert not core & {"node", "io", "cli", "fleet", "commands.replay", "bench.peers"}


def test_core_imports_with_ros_and_bag_libraries_blocked():
    imports = "".join(f"import ship_ident.{name}\n" for name in core_modules())
    check = f"for name in {BLOCKED!r}:\n    assert name not in sys.modules, name\n"
    process = subprocess.run([sys.executable, "-c", BLOCKER + imports + check], capture_output=True, text=True,
                             cwd=PACKAGE.parent, timeout=120)
    assert process.returncode == 0, process.stderr.strip().splitlines()[-1:]


def test_the_blocker_blocks():
    process = subprocess.run([sys.executable, "-c", BLOCKER + "import ship_ident.io\n"], capture_output=True,
                             text=True, cwd=PACKAGE.parent, timeout=120)
    assert process.returncode != 0 and "rosbags is blocked" in process.stderr
