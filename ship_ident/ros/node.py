"""ROS 2 node ``ship_ident``: online Nomoto identification on the vessel computer.

A thin adapter around ``online.OnlineIdentifier``. Inputs (std_msgs/Float64,
SI, NED; or a sensor_msgs/Imu in ENU for heading and yaw rate) are stamped on
arrival with the node's clock, so ``use_sim_time`` with ``/clock`` works. A
timer checks the refit schedule and hands each refit to one worker thread
(between refits, the quick change test: ``OnlineIdentifier.watch``);
callbacks never wait for a fit, and a refit still running when the next is
due is skipped and reported. Outputs (``outputs``, as replay writes them):
``~/parameters`` (Float64MultiArray, names in ``layout.dim[0].label``; only
estimates with status OK, latched: transient local, depth 1), ``~/estimate``
(JSON String, every refit with its status), ``~/gain_band`` (K and its 95 %
band), ``~/predicted_yaw_rate`` (Vector3Stamped, rad/s in z: the estimate in
force run free from the measured state in runs of ``prediction_horizon`` s,
one value per yaw-rate sample, stamped with the sample's time and published
when its run ends) and ``/diagnostics``.
Every ``diagnosis_period`` the window is diagnosed (``diagnosis.onboard``) in a
child process at low priority, off the refit path: ``~/diagnosis`` (JSON
String: verdict, candidates, held-out error, noise floor, the ``ros2 param
set`` that adds the missing effect), ``~/held_out_error`` and
``~/noise_floor`` (Float64, rad/s: pooled since the model or vessel last changed, what the verdict
is read from) and a ``missing_effect`` WARN in ``/diagnostics``; with ``auto_add_effects``
the node adds (and may remove again) an effect itself, through its own
``effects`` parameter, and logs it.
Once per refit the ROS graph is checked for publishers of another message
type on the input topics (DDS never delivers those; reported). With
``log_directory`` set, every accepted estimate is appended to rotated
JSON-lines files there, so the history survives a restart. At start, unless
numba's cache holds them already, a child process at low priority compiles the
refit's numeric kernels into that cache (``online.warmup``; after an install
the first time) while the window fills.

Run: ``identifier_node --ros-args --params-file config/ship_ident.yaml``
(or ``python -m ship_ident.ros.node``). SIGINT and SIGTERM stop it cleanly.
"""

from __future__ import annotations

import os

# Each fit solves systems of a few columns: a BLAS thread pool only burns CPU. Set before numpy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import math  # noqa: E402
import signal  # noqa: E402
import sys
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import fields
from multiprocessing import get_context

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3, Vector3Stamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, String

from ..diagnosis.onboard import MIN_WINDOW_S, NICENESS, DiagnosisWorker, OnlineDiagnosis
from ..io.files import FLOAT64, IMU, Sample, imu_samples
from ..io.jsonio import dumps_json
from ..online.config import NODE_PARAMETERS, ConfigError, NodeSettings, OnlineConfig, spec, specs
from ..online.estimate_log import EstimateLog
from ..online.identifier import OnlineIdentifier
from ..online.outputs import (
    DIAGNOSTIC_NAME,
    GAIN_BAND_LABELS,
    PREDICTION_FRAME,
    YawRatePrediction,
    diagnostic_status,
    error_and_floor,
    gain_band,
    trusted_parameters,
)
from ..online.warmup import kernels_cached, warm_up_quietly

NODE_NAME = "ship_ident"
# The schedule is checked this many times per refit period, and between refits the newest data are
# watched for a change as often (twice as often, as replay does, made the diagnosis child miss its
# verdicts at 5x playback: test_node's gyro-bias test): the gain follow runs at most this often.
TICKS_PER_REFIT = 5
# Float64 inputs are stamped on arrival; two messages of one input at one clock reading share a stamp.
# ros2 bag play --clock ticks at 40 Hz of wall time: at --rate 10 every 0.25 s of bag time, so most
# of a 10 Hz input would be rejected as duplicates.
STALLED_CLOCK = (
    "{} of them arrived with the node clock where their input's previous message had left it (Float64 "
    "inputs are stamped on arrival): with use_sim_time, /clock must advance between an input's "
    "messages (ros2 bag play --clock-topics-all, or --clock above the play rate times the input rate)"
)

RELIABILITY = {
    name: getattr(ReliabilityPolicy, name.upper()) for name in spec(NodeSettings, "qos_reliability").options()
}
CONFIG_NAMES = OnlineConfig.field_names()
SETTING_NAMES = [f.name for f in fields(NodeSettings)]
DIAGNOSTIC_LEVELS = {0: DiagnosticStatus.OK, 1: DiagnosticStatus.WARN, 2: DiagnosticStatus.ERROR}
# ~/parameters: what an autopilot steers by, latched so that one starting late gets the last trusted
# estimate at once (its subscription must be transient local too to receive it)
LATCHED = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def parameter_descriptors() -> dict:
    """{name: (default, ParameterDescriptor)} of every node parameter, built from its one definition
    (``online.config``): description with the unit, range, registry names, read-only."""
    out = {}
    for name, (default, s) in specs(*NODE_PARAMETERS).items():
        descriptor = ParameterDescriptor(
            description=s.description + (f" [{s.unit}]" if s.unit else ""),
            read_only=s.read_only,
            additional_constraints=s.range_text() if s.choices else "",
        )
        if isinstance(default, tuple):
            descriptor.type = ParameterType.PARAMETER_STRING_ARRAY
            default = list(default)
        if s.limits and isinstance(default, float):
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(s.limits[0]), to_value=float(s.limits[1]))
            ]
        elif s.limits and isinstance(default, int):
            descriptor.integer_range = [IntegerRange(from_value=s.limits[0], to_value=s.limits[1], step=1)]
        out[name] = (default, descriptor)
    return out


class IdentifierNode(Node):
    """The ``ship_ident`` node (see module docstring)."""

    def __init__(self, **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        for name, (value, descriptor) in parameter_descriptors().items():
            self.declare_parameter(name, value, descriptor)
        self.identifier = OnlineIdentifier(self._config_from_parameters())  # ConfigError on bad values
        settings = NodeSettings(**{name: self.get_parameter(name).value for name in SETTING_NAMES}).validate()
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=settings.qos_depth,
            reliability=RELIABILITY[settings.qos_reliability],
        )
        self._expected_types = self._subscribe(self.identifier.config, qos)
        self.estimate_log = (
            EstimateLog(settings.log_directory, settings.log_max_bytes, settings.log_backups)
            if settings.log_directory
            else None
        )
        self.parameters_pub = self.create_publisher(Float64MultiArray, "~/parameters", LATCHED)
        self.estimate_pub = self.create_publisher(String, "~/estimate", 10)
        self.gain_band_pub = self.create_publisher(Float64MultiArray, "~/gain_band", 10)
        # a run of prediction_horizon s at the input rate comes at once: the depth holds a run at 100 Hz
        self.predicted_pub = self.create_publisher(Vector3Stamped, "~/predicted_yaw_rate", 1000)
        self.diagnostics_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.diagnosis_pub = self.create_publisher(String, "~/diagnosis", 10)
        self.held_out_error_pub = self.create_publisher(Float64, "~/held_out_error", 10)
        self.noise_floor_pub = self.create_publisher(Float64, "~/noise_floor", 10)
        self.prediction = YawRatePrediction(self.identifier.config)
        worker = DiagnosisWorker()
        config = self.identifier.config
        if config.diagnosis_period > 0 and config.window_length >= MIN_WINDOW_S:
            worker.start()  # its imports run while the window fills
        self.diagnosis = OnlineDiagnosis(worker, self.get_fully_qualified_name())
        self._auto_effects = None  # effects auto-add asked for, set from the executor thread
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="refit")
        self._running = None  # Future of the refit in progress
        self._watching = None  # Future of the change watch between refits (queued refits wait for it)
        self._overruns = 0  # refits skipped since the last published record
        self._overrun_lock = threading.Lock()
        self._stalled = 0  # Float64 messages since the last refit rejected as duplicates: the clock stood still
        self._stall_lock = threading.Lock()
        self._callback_errors = 0
        self._type_problems = ""  # sentence about wrong-type publishers on the inputs, if any
        self._timer = None
        self._start_timer(config.refit_period)
        # the kernels a refit calls compiled into numba's cache while the window fills, by a child at low
        # priority: the node's own refits keep the CPU and the GIL, and its first one loads them
        self._warm_up = None
        if kernels_cached():
            self.get_logger().info("refit kernels found compiled in numba's cache")
        else:
            self._warm_up = get_context("spawn").Process(target=warm_up_quietly, name="ship_ident warm-up", daemon=True)
            self._warm_up.start()
            os.setpriority(os.PRIO_PROCESS, self._warm_up.pid, NICENESS)
            self.get_logger().info("compiling the refit kernels into numba's cache in a child process")
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self.get_logger().info(
            f"identifying {config.structure().label()} with {config.method}: window "
            f"{config.window_length:g} s, refit every {config.refit_period:g} s"
        )

    # --- configuration ---------------------------------------------------
    def _config_from_parameters(self, overrides: dict | None = None) -> OnlineConfig:
        values = {name: self.get_parameter(name).value for name in CONFIG_NAMES}
        values.update(overrides or {})
        return OnlineConfig(**values).validate()

    def _check_parameters(self, parameters) -> SetParametersResult:
        """Reject a change that would give an unusable configuration, saying why."""
        changes = {p.name: p.value for p in parameters if p.name in CONFIG_NAMES}
        try:
            self._config_from_parameters(changes)
        except (ConfigError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters) -> None:
        """Accepted changes take effect at the next refit."""
        old_period = self.identifier.config.refit_period
        self.identifier.reconfigure(self._config_from_parameters())
        config = self.identifier.config
        if config.refit_period != old_period:
            self._start_timer(config.refit_period)
        self.get_logger().info(
            f"from the next refit: {config.structure().label()} with "
            f"{config.method}, window {config.window_length:g} s, "
            f"refit every {config.refit_period:g} s"
        )

    def _start_timer(self, refit_period: float) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
        self._timer = self.create_timer(refit_period / TICKS_PER_REFIT, self._on_tick)

    # --- inputs ----------------------------------------------------------
    def _subscribe(self, config: OnlineConfig, qos: QoSProfile) -> dict:
        """Subscribe to the inputs; return {fully qualified topic: expected message type}."""
        roles = {"rudder": config.rudder_topic, "speed": config.speed_topic}
        expected = {}
        if config.imu_topic:
            subscription = self.create_subscription(Imu, config.imu_topic, self._on_imu, qos)
            expected[subscription.topic_name] = IMU
        else:
            roles.update(heading=config.heading_topic, yaw_rate=config.yaw_rate_topic)
        for role, topic in roles.items():
            if topic:
                subscription = self.create_subscription(
                    Float64, topic, lambda msg, role=role: self._on_value(role, msg.data), qos
                )
                expected[subscription.topic_name] = FLOAT64
        return expected

    def _check_topic_types(self) -> str:
        """A sentence naming input topics that also carry another message type ('' when none)."""
        graph = dict(self.get_topic_names_and_types())
        wrong = [
            f"{topic} carries {', '.join(t for t in graph[topic] if t != expected)} (expected {expected})"
            for topic, expected in self._expected_types.items()
            if any(t != expected for t in graph.get(topic, ()))
        ]
        if not wrong:
            return ""
        return "; ".join(wrong) + ": those messages are never received; fix the publisher or remap the topic"

    def _now(self) -> float:
        """Node clock time in s (simulated time when use_sim_time is set)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _on_value(self, role: str, value) -> None:
        try:
            self._take(Sample(self._now(), role, float(value)))
        except Exception as exc:  # a message must never stop the node
            self._report_callback_error(exc)

    def _on_imu(self, msg: Imu) -> None:
        try:
            for sample in imu_samples(msg, self._now()):
                self._take(sample)
        except Exception as exc:  # a message must never stop the node
            self._report_callback_error(exc)

    def _take(self, sample: Sample) -> None:
        """An input sample into the window and, when accepted, the prediction stream (whose run it
        may end: that run's predicted yaw rates are published)."""
        outcome = self.identifier.add(sample)
        if outcome == "accepted":
            self._publish_predictions(self.prediction.add(sample))
        elif outcome == "duplicate":
            with self._stall_lock:  # stamped on arrival: the clock stood still since its last message
                self._stalled += 1

    def _publish_predictions(self, predicted: list[tuple[float, float]]) -> None:
        for stamp, value in predicted:
            message = Vector3Stamped(vector=Vector3(x=math.nan, y=math.nan, z=value))
            seconds = math.floor(stamp)
            message.header.stamp = Time(sec=int(seconds), nanosec=min(int(round((stamp - seconds) * 1e9)), 999_999_999))
            message.header.frame_id = PREDICTION_FRAME
            self.predicted_pub.publish(message)

    def _report_callback_error(self, exc: Exception) -> None:
        self._callback_errors += 1
        self.get_logger().warning(f"input dropped: {type(exc).__name__}: {exc}", throttle_duration_sec=5.0)

    # --- refits ----------------------------------------------------------
    def _on_tick(self) -> None:
        if self._warm_up is not None and not self._warm_up.is_alive():  # reaps the finished warm-up child
            self._warm_up = None
        effects, self._auto_effects = self._auto_effects, None
        if effects is not None:
            result = self.set_parameters([Parameter("effects", Parameter.Type.STRING_ARRAY, list(effects))])[0]
            if not result.successful:
                self.get_logger().error(f"auto-add could not set effects {list(effects)}: {result.reason}")
        now = self._now()
        if not self.identifier.due(now):
            if all(job is None or job.done() for job in (self._running, self._watching)):
                self._watching = self._worker.submit(self._watch)
            return
        if self._running is not None and not self._running.done():
            self.identifier.skip(now)
            with self._overrun_lock:
                self._overruns += 1
            return
        try:
            self._type_problems = self._check_topic_types()
        except Exception as exc:  # a graph query must never stop the node
            self._report_callback_error(exc)
        self._running = self._worker.submit(self._refit)

    def _watch(self) -> None:
        """Worker thread: between refits, the quick change test (``OnlineIdentifier.watch``, rate
        limited there) at the clock's time when it runs; a change found is refitted and published at once."""
        try:
            changed = self.identifier.watch(self._now())
        except Exception as exc:  # a watch must never stop the node
            self.get_logger().error(f"change watch failed: {type(exc).__name__}: {exc}")
            return
        if changed:
            self._refit()

    def _refit(self) -> None:
        """Worker thread: refit at the clock's time when the job runs, and publish; any failure is
        reported, never raised.

        A job that waited behind a slow one (a starved CPU) runs after samples stamped later than the
        tick that submitted it: handed the tick's time, the identifier would read a clock stepping
        back by more than ``clock_jump_threshold`` (a bag looping) and empty the window.
        """
        now = self._now()
        try:
            with self._stall_lock:  # read as the refit counts its rejected samples: a long fit overlaps
                stalled, self._stalled = self._stalled, 0  # the next period's messages
            record = self.identifier.refit(now)
            self.prediction.update(record, self.identifier.config)
            effects = self.diagnosis.after_refit(record, self.identifier)
            if effects is not None:
                self._auto_effects = effects
            with self._overrun_lock:
                overruns, self._overruns = self._overruns, 0
            if overruns:
                record.conditions["refit_overran"] = (
                    f"{overruns} refit(s) skipped: the previous refit was still running; "
                    "raise refit_period or choose a faster method"
                )
            if stalled and "rejected_samples" in record.conditions:
                record.conditions["rejected_samples"] += f"; {STALLED_CLOCK.format(stalled)}"
            if self._type_problems:
                record.conditions["wrong_message_type"] = self._type_problems
            if record.new_estimate and self.estimate_log is not None:
                try:
                    self.estimate_log.write(record.to_json())
                except OSError as exc:
                    record.conditions["estimate_log_failed"] = (
                        f"cannot append to {self.estimate_log.path}: {exc.strerror or exc}; "
                        "estimates are published but not logged"
                    )
            self._publish(record)
        except Exception as exc:
            self.get_logger().error(f"refit failed: {type(exc).__name__}: {exc}")
            failure = f"{type(exc).__name__}: {exc}"
            self._publish_diagnostics(2, f"refit failed: {failure}", [("condition/refit_failed", failure)])

    def _publish(self, record) -> None:
        self.estimate_pub.publish(String(data=dumps_json(record.to_json())))
        trusted = trusted_parameters(record)
        if trusted is not None:
            self.parameters_pub.publish(multi_array(*trusted))
        band = gain_band(record)
        if band is not None:
            self.gain_band_pub.publish(multi_array(GAIN_BAND_LABELS, band))
        level, message, values = diagnostic_status(record, {"callback_errors": self._callback_errors})
        self._publish_diagnostics(level, message, values)
        if record.diagnosis is not None:
            self._publish_diagnosis(record.diagnosis)

    def _publish_diagnosis(self, diagnosis: dict) -> None:
        """``~/diagnosis`` (JSON), ``~/held_out_error`` and ``~/noise_floor`` (rad/s, pooled: the
        verdict's figures, ``outputs.error_and_floor``) and auto-add's announcement in the log."""
        self.diagnosis_pub.publish(String(data=dumps_json(diagnosis)))
        finished = error_and_floor(diagnosis)
        if finished is not None:
            self.held_out_error_pub.publish(Float64(data=finished[0]))
            self.noise_floor_pub.publish(Float64(data=finished[1]))
        auto_add = diagnosis.get("auto_add")
        if auto_add and auto_add["action"] == "kept":  # one severity per call site (rclpy's rule)
            self.get_logger().info(f"auto-add: {auto_add['sentence']}")
        elif auto_add:
            self.get_logger().warning(f"auto-add: {auto_add['sentence']}")

    def _publish_diagnostics(self, level: int, message: str, values: list) -> None:
        status = DiagnosticStatus(
            level=DIAGNOSTIC_LEVELS[level],
            name=DIAGNOSTIC_NAME,
            message=message,
            hardware_id=self.get_fully_qualified_name(),
            values=[KeyValue(key=k, value=v) for k, v in values],
        )
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self.diagnostics_pub.publish(array)

    def shutdown(self) -> None:
        """Stop the timer and wait for a refit in progress."""
        self.destroy_timer(self._timer)
        self._worker.shutdown(wait=True, cancel_futures=True)
        self.diagnosis.close()
        if self._warm_up is not None and self._warm_up.is_alive():
            self._warm_up.terminate()
            self._warm_up.join(timeout=5.0)


def multi_array(names, values) -> Float64MultiArray:
    """Values with their names comma-separated in ``layout.dim[0].label``."""
    message = Float64MultiArray(data=[float(v) for v in values])
    message.layout.dim = [MultiArrayDimension(label=",".join(names), size=len(names), stride=len(names))]
    return message


def make_executor():
    """rclpy's EventsExecutor where the ROS install has it (Kilted on), else SingleThreadedExecutor.

    The events executor dispatches in C++: at 100 Hz inputs the single-threaded executor's wait-set
    bookkeeping in Python held the interpreter lock 80 % of the time, and refits ran 6 times slower
    than offline."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return SingleThreadedExecutor()
    return EventsExecutor()


def main(argv=None) -> int:
    """Console script ``identifier_node``: spin until SIGINT or SIGTERM."""
    argv = sys.argv if argv is None else argv
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    try:
        node = IdentifierNode()
    except (ConfigError, rclpy.exceptions.ParameterException) as exc:
        print(f"identifier_node: error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    executor = make_executor()
    executor.add_node(node)
    try:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
    finally:
        # The events executor dispatches the node's timer and QoS events from C++: it is detached,
        # shut down and dropped before any of the node's entities is destroyed (an entity destroyed
        # under it, or it destroyed after the node, leaves it freed memory: SIGSEGV on exit).
        executor.remove_node(node)
        executor.shutdown()
        del executor
        node.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
