"""The package builds with colcon into a ROS 2 install space whose executables start."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import once_per_run
from node_play import play_to_the_end

PACKAGE_ROOT = Path(__file__).parents[1]
VENV_BIN = Path(sys.executable).parent
NOT_SOURCES = shutil.ignore_patterns(
    ".venv", ".git", "build", "install", "log", "__pycache__", "*.egg-info", ".pytest_cache", "out"
)

pytestmark = [pytest.mark.slow, pytest.mark.node]  # builds the package and starts its node


def build_workspace(root: Path) -> None:
    """A colcon workspace in ``root`` holding a copy of the package, built with the venv's colcon."""
    shutil.copytree(PACKAGE_ROOT, root / "src" / "ship_ident", ignore=NOT_SOURCES)
    env = dict(os.environ, PATH=f"{VENV_BIN}{os.pathsep}{os.environ.get('PATH', '')}")
    result = subprocess.run(
        ["colcon", "build", "--base-paths", "src"], cwd=root, env=env, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stdout + result.stderr


@pytest.fixture(scope="module")
def workspace(run_folder):
    """The built workspace, once per run: the test workers share it."""
    return once_per_run(run_folder, "colcon_ws", build_workspace)


def run_sourced(workspace: Path, command: str) -> subprocess.CompletedProcess:
    """Run ``command`` in bash after sourcing the install space (as ``ros2 run`` would see it)."""
    env = dict(
        os.environ, AMENT_PREFIX_PATH=str(VENV_BIN.parent), PATH=f"{VENV_BIN}{os.pathsep}{os.environ.get('PATH', '')}"
    )
    return subprocess.run(
        ["bash", "-c", f"source install/setup.bash && {command}"],
        cwd=workspace,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_colcon_installs_executables_and_ament_marker(workspace):
    install = workspace / "install" / "ship_ident"
    assert (install / "share" / "ament_index" / "resource_index" / "packages" / "ship_ident").is_file()
    assert (install / "share" / "ship_ident" / "package.xml").is_file()
    assert (install / "share" / "ship_ident" / "bags" / "demo_seed001.mcap").is_file()
    share = install / "share" / "ship_ident"
    for shipped in (
        "launch/ship_ident.launch.py",
        "config/ship_ident.yaml",
        "config/foxglove_layout.json",
        "config/plotjuggler_layout.xml",
    ):
        assert (share / shipped).read_bytes() == (PACKAGE_ROOT / shipped).read_bytes(), shipped
    for executable in ("identifier_node", "ship-ident"):
        path = install / "lib" / "ship_ident" / executable
        assert path.is_file() and os.access(path, os.X_OK), path


def test_built_ship_ident_starts_from_the_install_space(workspace):
    result = run_sourced(workspace, "install/ship_ident/lib/ship_ident/ship-ident --help")
    assert result.returncode == 0, result.stderr
    assert "simulate" in result.stdout and "identify" in result.stdout
    where = run_sourced(workspace, "python -c 'import ship_ident; print(ship_ident.__file__)'")
    assert str(workspace / "install") in where.stdout, where.stdout + where.stderr


def test_built_identifier_node_with_the_params_file_starts_and_identifies(workspace, tmp_path):
    """What `ros2 run ship_ident identifier_node --ros-args --params-file ...` starts, fed the bundled
    bag at up to 20x, paced by the node: a fresh install space has no compiled kernels yet, so the
    node starts its warm-up child, and its first refit compiles them. The diagnosis is off (at 20x it
    would diagnose every 3 s of wall time); the node's diagnosis child is test_node's."""
    from ship_ident.io.files import read_samples
    from ship_ident.ros.demo import Listener, ros_environment, shut_down

    domain = 101  # outside the 1..100 range the other node tests draw from
    env = dict(
        ros_environment(domain, tmp_path),
        AMENT_PREFIX_PATH=str(VENV_BIN.parent),
        PATH=f"{VENV_BIN}{os.pathsep}{os.environ.get('PATH', '')}",
    )
    share = workspace / "install" / "ship_ident" / "share" / "ship_ident"
    command = (
        f"source install/setup.bash && exec install/ship_ident/lib/ship_ident/identifier_node "
        f"--ros-args --params-file {share / 'config' / 'ship_ident.yaml'} "
        "-p use_sim_time:=true -p diagnosis_period:=0.0"
    )
    node = subprocess.Popen(
        ["bash", "-c", command], cwd=workspace, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    listener = Listener(domain)
    stalled = None
    try:
        play_to_the_end(listener, read_samples(share / "bags" / "demo_seed001.mcap"), 20.0)
    except TimeoutError as exc:  # failed below, with what the node printed
        stalled = exc
    finally:
        code, log = shut_down(node, listener)
    assert stalled is None, f"{stalled}; the node printed:\n{log}"
    assert code == 0, log
    assert "compiling the refit kernels into numba's cache in a child process" in log, log
    truth = json.loads((share / "bags" / "demo_seed001.truth.json").read_text())["parameters"]
    new = [e for e in listener.estimates if e["new_estimate"]]
    assert new, log
    assert new[-1]["parameters"]["K"] == pytest.approx(truth["K"], rel=0.05)
