"""``make demo``: the identification node live over DDS, fed by the bundled bag.

Starts ``identifier_node`` (use_sim_time) and ``ship-ident play`` as two
processes on a private ROS domain restricted to this machine, plays the
bundled 10-minute bag at 15x real time, listens to ``~/estimate`` and prints
the parameters as they converge beside the truth the bag was simulated
with. About a minute; Ctrl-C stops everything.

The helpers here (``ros_environment``, ``start_node``, ``start_play``, ``quiet_trip``,
``stop``, ``Listener``) are also what the node tests use.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repository: ship_ident/ros/demo.py
BAG = ROOT / "bags" / "demo_seed001.mcap"
TRUTH = ROOT / "bags" / "demo_seed001.truth.json"
CONFIG = ROOT / "config" / "ship_ident.yaml"
RATE = 15.0  # x real time
PRINT_EVERY = 30.0  # s of bag time between printed estimates


# Fast DDS's transports for the participants started here: UDP on the loopback, not its shared-memory
# transport. Started and stopped dozens of times a minute on one host, a participant's deletion locked a
# shared-memory port segment another participant's stop had just released, now and then (a node's exit
# under load, about one in sixty: SIGSEGV in SharedMemChannelResource::release); a vessel's own DDS
# configuration is its crew's.
TRANSPORTS = {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}


def ros_environment(domain_id: int, log_dir) -> dict:
    """A copy of os.environ for a child on its own ROS domain, discovery limited to this host
    (``TRANSPORTS``)."""
    env = dict(os.environ)
    env.update(
        ROS_DOMAIN_ID=str(domain_id),
        ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
        ROS_LOG_DIR=str(log_dir),
        PYTHONUNBUFFERED="1",
        **TRANSPORTS,
    )
    return env


def start_node(env: dict, *parameters: str, params_file=CONFIG, **popen) -> subprocess.Popen:
    """``identifier_node`` as a child process; ``parameters`` are ``name:=value`` overrides."""
    command = [sys.executable, "-m", "ship_ident.ros.node", "--ros-args"]
    if params_file:
        command += ["--params-file", str(params_file)]
    for parameter in parameters:
        command += ["-p", parameter]
    return subprocess.Popen(command, env=env, **popen)


def start_play(env: dict, bag, rate: float, *options: str, **popen) -> subprocess.Popen:
    """``ship-ident play`` as a child process, waiting up to 20 s for the node to subscribe."""
    command = [
        sys.executable,
        "-m",
        "ship_ident.cli",
        "play",
        str(bag),
        "--rate",
        str(rate),
        "--wait-for-subscribers",
        "20",
        *options,
    ]
    return subprocess.Popen(command, env=env, **popen)


NODE_LOG = "node.log"  # a quiet trip's node output (its ``log_dir``), read back by ``node_log_tail``


def quiet_trip(domain_id: int, log_dir, bag, rate: float, *parameters: str):
    """A quiet ``identifier_node`` on simulated time (``use_sim_time`` and ``parameters``,
    ``name:=value``), its output kept in ``log_dir``/NODE_LOG, a ``Listener`` collecting its
    outputs and ``bag`` played to it at ``rate``: ``(node, listener, play)``, to be ended with
    ``shut_down``. The node starts from its declared defaults (the parameter file's values), so a
    trip needs no checkout of the repository around the package."""
    env = ros_environment(domain_id, log_dir)
    with open(Path(log_dir) / NODE_LOG, "w") as log:  # the child keeps its own copy of the descriptor
        node = start_node(
            env, "use_sim_time:=true", *parameters, params_file=None, stdout=log, stderr=subprocess.STDOUT
        )
    listener = Listener(domain_id)
    return node, listener, start_play(env, bag, rate, stderr=subprocess.DEVNULL)


def node_log_tail(log_dir, lines: int = 12) -> str:
    """The last ``lines`` lines of a quiet trip's node output (``quiet_trip``), for a node that
    exited with an error: what it said before it died."""
    path = Path(log_dir) / NODE_LOG
    return "\n".join(path.read_text(errors="replace").splitlines()[-lines:]) if path.exists() else ""


def stop(process: subprocess.Popen, timeout: float = 5.0):
    """SIGINT, wait, then kill: returns (returncode, stdout, stderr)."""
    if process.poll() is None:
        process.send_signal(2)
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
    return process.returncode, out, err


# s: SIGINT to a node's exit. The node finishes the refit in progress before it exits (compiled code
# cannot be interrupted), and a cold refit of a model just changed takes seconds, more on a loaded machine.
NODE_STOP_TIMEOUT = 30.0


def shut_down(node: subprocess.Popen, listener, *feeders: subprocess.Popen | None) -> tuple[int, str]:
    """Stop the feeders (e.g. ``play``), then the node (SIGINT, killed after NODE_STOP_TIMEOUT s),
    then close the listener; returns the node's exit code and its output."""
    for feeder in feeders:
        if feeder is not None:
            stop(feeder)
    code, out, _ = stop(node, NODE_STOP_TIMEOUT)
    listener.close()
    return code, out


HOLD_CALLBACKS = 5  # the node's outputs a pacing hold processes per /clock stamp (its stream: about one)
STALL_S = 10.0  # s of wall time without a new record after which a pacing hold takes a skipped refit
CLOCK_REPEAT_S = 1.0  # s of wall time between the /clock messages a pacing hold sends again while it waits


class Listener:
    """An in-process rclpy node on its own context that collects the identifier's outputs."""

    def __init__(self, domain_id: int, node_name: str = "ship_ident", latched_parameters: bool = False):
        """``latched_parameters``: subscribe to ``~/parameters`` as an autopilot does (transient local,
        depth 1: the last trusted estimate arrives at once, however late the subscription)."""
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import Vector3Stamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from std_msgs.msg import Float64, Float64MultiArray, String

        os.environ.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", **TRANSPORTS)
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("ship_ident_listener", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.estimates: list[dict] = []
        self.parameters: list = []
        self.diagnostics: list = []
        self.diagnoses: list[dict] = []  # ~/diagnosis
        self.held_out_errors: list[float] = []  # ~/held_out_error, rad/s
        self.predicted: list[tuple[float, float]] = []  # ~/predicted_yaw_rate: (stamp s, rad/s)
        self.node.create_subscription(
            String, f"/{node_name}/estimate", lambda m: self.estimates.append(json.loads(m.data)), 100
        )
        parameters_qos = (
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
            if latched_parameters
            else 100
        )
        self.node.create_subscription(
            Float64MultiArray, f"/{node_name}/parameters", self.parameters.append, parameters_qos
        )
        self.node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: self.diagnostics.extend(m.status), 100)
        self.node.create_subscription(
            String, f"/{node_name}/diagnosis", lambda m: self.diagnoses.append(json.loads(m.data)), 100
        )
        self.node.create_subscription(
            Float64, f"/{node_name}/held_out_error", lambda m: self.held_out_errors.append(m.data), 100
        )
        self.node.create_subscription(
            Vector3Stamped,
            f"/{node_name}/predicted_yaw_rate",
            lambda m: self.predicted.append((m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, m.vector.z)),
            1000,
        )

    def spin(self, seconds: float, until=None) -> bool:
        """Process messages for up to ``seconds``; stop early once ``until()`` is true."""
        deadline = time.monotonic() + seconds
        while (remaining := deadline - time.monotonic()) > 0:
            self.executor.spin_once(timeout_sec=min(0.05, remaining))
            if until is not None and until():
                return True
        return until is None

    def newest_refit(self) -> float | None:
        """The stamp (s, node clock) of the newest estimate record received, None before the first."""
        return self.estimates[-1]["stamp"] if self.estimates else None

    def pace_by_node(self, lead, timeout: float, skipped: float = 0.0, clock=None):
        """A ``Player.play`` hold that keeps /clock at most ``lead`` s (simulated) past the node's
        newest refit, waiting up to ``timeout`` s of wall time for the node to catch up (and
        processing the node's outputs meanwhile): a node starved of CPU slows the play, not loses
        samples stamped on arrival. ``lead`` is a number, or a function of the listener giving it
        (a tighter lead while the node publishes at every tick of its timer). For every STALL_S s
        of wall time without a new record, the lead grows by ``skipped`` s until the next record:
        a refit that came due while the previous one was still running (a first refit compiling
        its kernels, a starved CPU) was skipped, and the next one is due a period later. ``clock``
        (``Player.republish_clock``) is called every CLOCK_REPEAT_S s while the hold waits: the
        node takes /clock best effort, and a message lost then is never followed by a newer one.
        Raises TimeoutError saying how far the node got."""
        stalls = {"at": None, "count": 0}  # the newest record's stamp at the last stall, and the stalls since it

        def allowed() -> float:
            extra = (
                skipped * stalls["count"] if stalls["at"] is not None and stalls["at"] == self.newest_refit() else 0.0
            )
            return (lead(self) if callable(lead) else lead) + extra

        def hold(stamp: float) -> None:
            for _ in range(HOLD_CALLBACKS):
                self.executor.spin_once(timeout_sec=0)
            if self.newest_refit() is None or stamp - self.newest_refit() <= allowed():
                return
            now = time.monotonic()
            deadline, seen, quiet_since = now + timeout, self.newest_refit(), now
            while (remaining := deadline - time.monotonic()) > 0:
                if self.spin(min(CLOCK_REPEAT_S, remaining), lambda: stamp - self.newest_refit() <= allowed()):
                    return
                if clock is not None:
                    clock()
                if self.newest_refit() != seen:
                    seen, quiet_since = self.newest_refit(), time.monotonic()
                elif time.monotonic() - quiet_since >= STALL_S:  # nothing new: a refit was skipped
                    stalls["count"] = stalls["count"] + 1 if stalls["at"] == seen else 1
                    stalls["at"], quiet_since = seen, time.monotonic()
                    if stamp - seen <= allowed():
                        return
            raise TimeoutError(
                f"the node's newest refit is at {self.newest_refit():g} s, the clock at {stamp:g} s, "
                f"after {timeout:g} s of waiting"
            )

        return hold

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _row(label: str, params: dict, names: list, truth: dict | None = None) -> str:
    cells = []
    for name in names:
        value = params.get(name, math.nan)
        if truth and name in ("K", "T1") and truth.get(name):
            cells.append(f"{value:9.4f} {100 * (value / truth[name] - 1):+5.1f}%")
        else:
            cells.append(f"{value:9.4f}       " if name in ("K", "T1") else f"{value:9.4f}")
    return f"{label:>10} " + " ".join(cells)


def main() -> int:
    truth = json.loads(TRUTH.read_text())["parameters"]
    names = list(truth)
    domain_id = 20 + os.getpid() % 80
    header = f"{'bag time':>10} " + " ".join(f"{n:>9}       " if n in ("K", "T1") else f"{n:>9}" for n in names)
    print(f"ship_ident demo: node + bag {BAG.name} at {RATE:g}x over DDS (domain {domain_id})")
    with tempfile.TemporaryDirectory(prefix="ship_ident_demo_") as log_dir:
        env = ros_environment(domain_id, log_dir)
        node_log = open(Path(log_dir) / "node.log", "w+")
        node = start_node(env, "use_sim_time:=true", stdout=node_log, stderr=subprocess.STDOUT)
        listener = Listener(domain_id)
        play = None
        try:
            play = start_play(env, BAG, RATE, stdout=subprocess.DEVNULL)
            print(f"estimates every {PRINT_EVERY:g} s of bag time (K and T1 with their error)\n")
            print(header)
            print(_row("truth", truth, names))
            started = time.monotonic()
            printed = [-math.inf]
            while play.poll() is None:
                listener.spin(0.2)
                _print_new(listener, truth, names, printed)
            listener.spin(2.0)  # the last refits
            _print_new(listener, truth, names, printed)
            status = _summary(listener, truth, names, time.monotonic() - started)
            if status:
                node_log.seek(0)
                print("node log:\n" + node_log.read()[-2000:])
            return status
        except KeyboardInterrupt:
            print("\ninterrupted")
            return 130
        finally:
            shut_down(node, listener, play)
            node_log.close()


def _print_new(listener: Listener, truth: dict, names: list, printed: list) -> None:
    """Print the newest estimate once PRINT_EVERY s of bag time passed since the last printed one."""
    fresh = [e for e in listener.estimates if e["parameters"] and e["stamp"] >= printed[0] + PRINT_EVERY]
    if fresh:
        printed[0] = fresh[-1]["stamp"]
        print(_row(f"{printed[0]:.0f} s", fresh[-1]["parameters"], names, truth), flush=True)


def _summary(listener: Listener, truth: dict, names: list, wall: float) -> int:
    final = next((e for e in reversed(listener.estimates) if e["parameters"]), None)
    if final is None:
        print("no estimate arrived: the node got no data (see its log above)")
        return 1
    print(_row("final", final["parameters"], names, truth))
    errors = {n: 100 * (final["parameters"][n] / truth[n] - 1) for n in ("K", "T1") if truth.get(n)}
    refit = [e["compute_seconds"] for e in listener.estimates if e.get("new_estimate")]
    print(
        f"\n{len(listener.estimates)} refits in {wall:.0f} s; last status {final['status']}"
        + (f" ({', '.join(final['conditions'])})" if final["conditions"] else "")
    )
    print(
        "errors against truth: "
        + ", ".join(f"{n} {e:+.1f} %" for n, e in errors.items())
        + f"; free-run yaw-rate rmse {math.degrees(final['fit']['rmse_yaw_rate']):.3f} deg/s"
    )
    if refit:
        print(
            f"refit compute time: median {1000 * sorted(refit)[len(refit) // 2]:.0f} ms, max {1000 * max(refit):.0f} ms"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
