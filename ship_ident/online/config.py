"""The online identifier's configuration and the node's own settings, each value defined once.

Every field carries its unit, range (inclusive), description, whether it is read-only at run time
and, where the values are names, the registry they come from (``parameter``). From these one
definition come: the validation here (``check_fields`` plus the checks across fields in
``OnlineConfig.validate``), the node's ROS parameter descriptors (``node.py``), ``replay``'s
options (``commands/replay.py``), ``config/ship_ident.yaml`` and the parameter table of
``docs/node.md``. ``python -m ship_ident.online.config`` rewrites both files from it;
``test/test_parameters.py`` checks that they match.
"""

from __future__ import annotations

import json
import math
import re
import sys
import textwrap
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from ..estimators import DEFAULT_METHOD, make_estimator, method_names
from ..estimators.base import MIN_RUDDER_STD
from ..model.effects import EFFECTS
from ..model.structure import BASE_MODELS, Structure, StructureError, parse_effects
from .samples import Topics

DEFAULT_TOPICS = Topics()

# A stored sample costs about 110 bytes (a tuple of two floats in a deque): one million per input,
# four inputs, is about 0.4 GB, the most a vessel computer should give to the window.
MAX_WINDOW_SAMPLES = 1_000_000
GAP_SAMPLES = 5  # gap_threshold 0: an input pause of this many sample times splits
ESTIMATE_LOG_MIN_BYTES = 1000  # a smaller rotation size would rotate at every line

# The groups of the parameter file, in its order.
GROUPS = (
    "inputs",
    "window and schedule",
    "model",
    "checks and diagnostics",
    "change detection (loading, fouling, damage: a new response restarts the window)",
    "diagnosis on board (which catalogued effect the model misses, while sailing)",
    "estimate log",
)


class ConfigError(ValueError):
    """An online configuration value out of range or unknown; the message says which and why."""


@dataclass(frozen=True)
class Spec:
    """What a configuration field means: unit ('' for none), inclusive range, description, whether
    it is fixed at start (read-only), the registry its names come from, its group in the file."""

    description: str
    unit: str = ""
    limits: tuple | None = None
    read_only: bool = False
    choices: Callable[[], object] | None = None  # a registry's names, read when asked
    many: bool = False  # a list of choices (each at most once), not one
    group: str = GROUPS[0]

    def options(self) -> tuple[str, ...]:
        return tuple(self.choices()) if self.choices else ()

    def range_text(self) -> str:
        """'0.01 to 1', 'one of a, b', 'any of a, b' or ''."""
        if self.limits:
            return " to ".join(str(x) if isinstance(x, int) else f"{x:g}" for x in self.limits)
        if self.choices:
            return f"{'any' if self.many else 'one'} of {', '.join(self.options())}"
        return ""


def parameter(default, description: str, unit="", limits=None, read_only=False, choices=None, many=False, group=""):
    """A dataclass field with its ``Spec`` as metadata (see ``spec``)."""
    return field(
        default=default,
        metadata={"spec": Spec(description, unit, limits, read_only, choices, many, group or GROUPS[0])},
    )


def spec(cls, name: str) -> Spec:
    """The ``Spec`` (unit, range, description) of one field of a configuration class.

    Parameters
    ----------
    cls : type
        ``OnlineConfig`` or ``NodeSettings``.
    name : str
        The field's name.

    Returns
    -------
    Spec
        Its specification.
    """
    return next(f.metadata["spec"] for f in fields(cls) if f.name == name)


def specs(*classes) -> dict:
    """Every field of ``classes`` with its default and specification, in the order of the parameter file.

    Parameters
    ----------
    *classes : type
        Configuration dataclasses (``OnlineConfig``, ``NodeSettings``).

    Returns
    -------
    dict
        {name: (default, Spec)}, grouped as ``config/ship_ident.yaml`` lists them.
    """
    found = [(f.name, f.default, f.metadata["spec"]) for cls in classes for f in fields(cls)]
    found.sort(key=lambda item: GROUPS.index(item[2].group))
    return {name: (default, s) for name, default, s in found}


def check_fields(values) -> None:
    """Raise ConfigError for the first field of a configuration dataclass out of its Spec: a number
    outside its range (or not finite, or a float for an integer), a name not in its registry."""
    for f in fields(values):
        s, value = f.metadata["spec"], getattr(values, f.name)
        kind = type(f.default)
        if s.limits:
            number = isinstance(value, (int, float)) and not isinstance(value, bool)
            if not number or (kind is int and not isinstance(value, int)):
                raise ConfigError(f"{f.name} must be {'an integer' if kind is int else 'a number'}, got {value!r}")
            low, high = s.limits
            if not (math.isfinite(value) and low <= value <= high):
                raise ConfigError(
                    f"{f.name} must be in [{low:g}, {high:g}]{' ' + s.unit if s.unit else ''} "
                    f"({s.description}), got {value!r}"
                )
        elif s.choices and not s.many and value not in s.options():
            raise ConfigError(f"unknown {f.name} {value!r}; choose from {', '.join(s.options())}")
        elif kind is str and not isinstance(value, str):
            raise ConfigError(f"{f.name} must be a string, got {value!r}")
        elif kind is bool and not isinstance(value, bool):
            raise ConfigError(f"{f.name} must be true or false, got {value!r}")


def _model_description() -> str:
    return "base model: " + " or ".join(
        f"{name} ({', '.join(p.name for p in params)})" for name, params in BASE_MODELS.items()
    )


TOPIC = "std_msgs/Float64, stamped on arrival with the node clock"
WINDOW, MODEL, CHECKS, CHANGE, DIAGNOSIS, LOG = GROUPS[1:]


@dataclass(frozen=True)
class OnlineConfig:
    """Everything the online identifier is configured with (SI units, angles NED)."""

    rudder_topic: str = parameter(
        DEFAULT_TOPICS.rudder, f"rudder angle topic ({TOPIC}), rad; positive gives positive yaw rate", read_only=True
    )
    heading_topic: str = parameter(
        DEFAULT_TOPICS.heading, f"heading topic ({TOPIC}), rad, NED, may be wrapped to (-pi, pi]", read_only=True
    )
    yaw_rate_topic: str = parameter(DEFAULT_TOPICS.yaw_rate, f"yaw rate topic ({TOPIC}), rad/s, NED", read_only=True)
    speed_topic: str = parameter(
        "", f"forward speed topic ({TOPIC}), m/s; empty: no speed input (speed_dependence needs one)", read_only=True
    )
    imu_topic: str = parameter(
        "",
        "sensor_msgs/Imu topic (ENU) for heading and yaw rate instead of heading_topic and yaw_rate_topic; "
        "empty: not used",
        read_only=True,
    )
    sample_time: float = parameter(0.1, "grid step the window is resampled to", "s", (0.01, 1.0), group=WINDOW)
    window_length: float = parameter(180.0, "data in each fit", "s", (10.0, 3600.0), group=WINDOW)
    refit_period: float = parameter(
        5.0,
        "time between refits; a refit still running when the next is due is skipped",
        "s",
        (0.1, 3600.0),
        group=WINDOW,
    )
    model: str = parameter("nomoto2", _model_description(), choices=BASE_MODELS.keys, group=MODEL)
    effects: tuple = parameter(
        ("rudder_offset", "cubic_yaw"), "effects added to the model", choices=EFFECTS.keys, many=True, group=MODEL
    )
    method: str = parameter(
        DEFAULT_METHOD,
        "estimator; +oe: output error (multiple shooting), +pem: prediction error (output error whitened "
        "by a Kalman filter that knows the rudder noise)",
        choices=method_names,
        group=MODEL,
    )
    min_window_length: float = parameter(
        60.0, "data needed before the first fit (at most window_length)", "s", (1.0, 3600.0), group=WINDOW
    )
    min_rudder_std: float = parameter(
        float(MIN_RUDDER_STD),
        f"rudder std below which a window gives no new estimate ({math.degrees(MIN_RUDDER_STD):g} deg)",
        "rad",
        (0.0, 0.5),
        group=CHECKS,
    )
    rudder_limit: float = parameter(
        math.radians(35.0),
        "the steering gear's limit (35 deg): a rudder held there for half the window is reported "
        "rudder_saturated (a zigzag's or a turn's held angle is not)",
        "rad",
        (0.01, 1.5708),
        group=CHECKS,
    )
    min_fit_correlation: float = parameter(
        0.8,
        "free-run yaw-rate correlation below which the fit is reported poor, as a share of the best its noise "
        "allows (sqrt(1 - noise^2 / variance) of the measured yaw rate)",
        "",
        (0.0, 1.0),
        group=CHECKS,
    )
    stale_timeout: float = parameter(
        1.0, "time without a sample before an input is reported stale", "s", (0.01, 3600.0), group=CHECKS
    )
    gap_threshold: float = parameter(
        0.0,
        f"time without a sample that splits the window into segments fitted apart (>= sample_time); "
        f"0: {GAP_SAMPLES} sample times",
        "s",
        (0.0, 3600.0),
        group=CHECKS,
    )
    clock_jump_threshold: float = parameter(
        1.0,
        "a clock step back this large resets the window and schedule; a step forward beyond "
        "max(this, refit_period) restarts the schedule",
        "s",
        (0.01, 3600.0),
        group=CHECKS,
    )
    max_window_samples: int = parameter(
        20000,
        "hard bound on stored samples per input (>= window_length / sample_time; about 110 bytes each, "
        f"{4 * 110 * MAX_WINDOW_SAMPLES / 1e9:.2f} GB for four inputs at the most); a faster input is "
        "reported window_truncated",
        "",
        (100, MAX_WINDOW_SAMPLES),
        group=WINDOW,
    )
    prediction_horizon: float = parameter(
        10.0,
        "length of each free run of ~/predicted_yaw_rate (the estimate in force run from the measured state over "
        "the measured rudder, restarted from the measurement after each run; a run is published when it ends) and "
        "of the free run behind the estimate record's predicted_yaw_rate",
        "s",
        (0.1, 3600.0),
        group=CHECKS,
    )
    change_ratio: float = parameter(
        9.0,
        "free-run yaw-rate error of the newest model fitted before the newest change_test_length s, as a "
        "multiple of its usual level (mean squares), beyond which on two refits in a row (or 4x it once from "
        "any sample of the newest refit period on, 20 samples at least; or above 3 with K refitted on them "
        "moved by > 15 %) the vessel counts as changed and the window restarts where it most likely changed "
        "(vessel_changed); "
        "0: never, else > 1",
        "",
        (0.0, 1e6),
        group=CHANGE,
    )
    change_test_length: float = parameter(
        30.0, "newest data the change test runs the model over", "s", (1.0, 3600.0), group=CHANGE
    )
    diagnosis_period: float = parameter(
        60.0,
        "time between diagnoses of the window (the model fitted on its older 65 %, run free on the newest "
        "35 %, every catalogued effect tried; ~/diagnosis, ~/held_out_error, missing_effect); 0: off, "
        "else >= refit_period",
        "s",
        (0.0, 86400.0),
        group=DIAGNOSIS,
    )
    auto_add_effects: bool = parameter(
        False,
        "add an effect found missing in auto_add_after consecutive diagnoses to effects (announced and "
        "logged), and remove it again when the held-out error does not fall within two diagnoses",
        group=DIAGNOSIS,
    )
    auto_add_after: int = parameter(
        3, "consecutive diagnoses naming the same effect before auto_add_effects adds it", "", (1, 100), group=DIAGNOSIS
    )

    def __post_init__(self):
        try:
            object.__setattr__(self, "effects", parse_effects(self.effects))
        except StructureError as exc:
            raise ConfigError(str(exc)) from None

    def validate(self) -> OnlineConfig:
        """Check every value against its range and the values against each other.

        Returns
        -------
        OnlineConfig
            ``self``, when all values are usable.

        Raises
        ------
        ConfigError
            Naming the first bad value, its unit and what it must be.
        """
        check_fields(self)
        if self.min_window_length > self.window_length:
            raise ConfigError(
                f"min_window_length must be <= window_length={self.window_length} s, got {self.min_window_length}"
            )
        if self.window_length < 20 * self.sample_time:
            raise ConfigError(
                f"window_length {self.window_length} s holds fewer than 20 samples of {self.sample_time} s"
            )
        if not (self.gap_threshold == 0 or self.sample_time <= self.gap_threshold):
            raise ConfigError(
                f"gap_threshold must be 0 ({GAP_SAMPLES} sample times) or >= sample_time "
                f"{self.sample_time} s, got {self.gap_threshold!r}"
            )
        if not (self.diagnosis_period == 0 or self.diagnosis_period >= self.refit_period):
            raise ConfigError(
                f"diagnosis_period must be 0 (off) or >= refit_period {self.refit_period} s, "
                f"got {self.diagnosis_period!r}"
            )
        if not (self.change_ratio == 0 or self.change_ratio > 1):
            raise ConfigError(f"change_ratio must be 0 (no change test) or > 1, got {self.change_ratio!r}")
        needed = max(int(math.ceil(self.window_length / self.sample_time)), 100)
        if self.max_window_samples < needed:
            raise ConfigError(
                f"max_window_samples {self.max_window_samples} cannot hold a "
                f"{self.window_length} s window at {self.sample_time} s (need >= {needed})"
            )
        for name in ("rudder_topic", "heading_topic", "yaw_rate_topic"):
            if not self.imu_topic and not getattr(self, name):
                raise ConfigError(f"{name} is empty; name the topic (or set imu_topic for heading and yaw rate)")
        try:
            structure = self.structure()
            make_estimator(self.method)
        except (StructureError, ValueError) as exc:
            raise ConfigError(str(exc)) from None
        if structure.needs_speed and not self.speed_topic:
            raise ConfigError("speed_dependence needs speed_topic set")
        return self

    def structure(self) -> Structure:
        """The model the identifier fits: ``model`` (nomoto1, nomoto2, ...) with ``effects``.

        Returns
        -------
        Structure
            Its parameters, bounds and simulation.
        """
        return Structure(self.model, self.effects)

    @property
    def gap(self) -> float:
        """s without a sample that splits the window: gap_threshold, or GAP_SAMPLES sample times."""
        return self.gap_threshold or GAP_SAMPLES * self.sample_time

    def changed(self, **values) -> OnlineConfig:
        """A validated copy with some values replaced.

        Parameters
        ----------
        **values
            Field names and their new values (SI units).

        Returns
        -------
        OnlineConfig
            The new configuration; raises ConfigError when a value is unusable.
        """
        return replace(self, **values).validate()

    @classmethod
    def field_names(cls) -> list[str]:
        """The names of the configuration's fields, in declaration order.

        Returns
        -------
        list of str
            Field names (node parameters of the same names).
        """
        return [f.name for f in fields(cls)]

    def to_json(self) -> dict:
        """The configuration as a JSON object.

        Returns
        -------
        dict
            Field name -> value (SI units; ``effects`` a list).
        """
        out = asdict(self)
        out["effects"] = list(self.effects)
        return out


@dataclass(frozen=True)
class NodeSettings:
    """The node's settings outside the identifier: input QoS and the estimate log (all read-only)."""

    qos_reliability: str = parameter(
        "best_effort",
        "input QoS reliability (best_effort: sensor data; a reliable publisher matches too)",
        read_only=True,
        choices=lambda: ("best_effort", "reliable"),
    )
    qos_depth: int = parameter(100, "input QoS history depth (messages kept per topic)", "", (1, 10000), True)
    log_directory: str = parameter(
        "",
        "directory of the JSON-lines log of every accepted estimate (estimates.jsonl, appended across "
        "restarts; an unwritable directory stops the start-up); empty: no log",
        read_only=True,
        group=LOG,
    )
    log_max_bytes: int = parameter(
        10_000_000,
        "size at which estimates.jsonl is rotated to estimates.jsonl.1",
        "bytes",
        (ESTIMATE_LOG_MIN_BYTES, 10**9),
        True,
        group=LOG,
    )
    log_backups: int = parameter(
        5, "rotated log files kept (estimates.jsonl.1 ...; the oldest is deleted)", "", (0, 1000), True, group=LOG
    )

    def validate(self) -> NodeSettings:
        """Check every value against its range.

        Returns
        -------
        NodeSettings
            ``self``, when all values are usable; raises ConfigError naming the first bad one.
        """
        check_fields(self)
        return self


NODE_PARAMETERS = (OnlineConfig, NodeSettings)  # every parameter of the node, in these two


# --- the generated files -----------------------------------------------------------------------
YAML_HEADER = """\
# Parameters of the ship_ident identification node (identifier_node).
#   identifier_node --ros-args --params-file config/ship_ident.yaml [-p name:=value ...]
# Generated from ship_ident/online/config.py (python -m ship_ident.online.config): edit there.
# Units are SI (s, rad, m/s); angles NED (positive clockwise seen from above).
# Floats are written as floats (250.0, not 250): rcl rejects an int for a float parameter.
# Changes at run time (ros2 param set / AsyncParameterClient) are validated and take effect
# at the next refit; read-only parameters (topics, QoS, the log) are fixed at start.
# Keyed /** (any node name, any namespace): it applies to a renamed or namespaced node as well
# (identifier_node --ros-args -r __ns:=/boat1 --params-file ...; the launch file's namespace).
/**:
  ros__parameters:
"""
TABLE_START = "<!-- parameters: generated by python -m ship_ident.online.config; edit there -->"
TABLE_END = "<!-- end of parameters -->"


def yaml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(value) + "]"
    if isinstance(value, str):
        return value if re.fullmatch(r"[A-Za-z_/][\w/+.-]*", value) else json.dumps(value)
    return repr(value)


def parameter_file() -> str:
    """``config/ship_ident.yaml``: every parameter with its default, grouped, each after a comment
    with its description, unit and range."""
    lines, group = [YAML_HEADER.rstrip("\n")], None
    for name, (default, s) in specs(*NODE_PARAMETERS).items():
        if s.group != group:
            group = s.group
            lines += ["", f"    # --- {group} ---"]
        extra = ", ".join(x for x in (s.unit, s.range_text(), "read-only" if s.read_only else "") if x)
        comment = s.description + (f" [{extra}]" if extra else "")
        lines += textwrap.wrap(comment, 112, initial_indent="    # ", subsequent_indent="    #   ")
        lines.append(f"    {name}: {yaml_value(default)}")
    return "\n".join(lines) + "\n"


def markdown_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(value) + "]"
    if isinstance(value, float):
        text = f"{value:.6g}"
        return text if "." in text or "e" in text else text + ".0"
    return str(value) if value != "" else '""'


def parameter_table() -> str:
    """The Markdown table of every node parameter: name, default, unit, range, description."""
    rows = [
        TABLE_START,
        "| parameter | default | unit | range | description |",
        "|---|---|---|---|---|",
    ]
    for name, (default, s) in specs(*NODE_PARAMETERS).items():
        description = s.description.replace("|", "\\|") + (" (read-only)" if s.read_only else "")
        rows.append(f"| `{name}` | `{markdown_value(default)}` | {s.unit} | {s.range_text()} | {description} |")
    return "\n".join(rows + [TABLE_END]) + "\n"


def with_table(markdown: str) -> str:
    """``markdown`` with the text between TABLE_START and TABLE_END replaced by ``parameter_table()``."""
    start, end = markdown.index(TABLE_START), markdown.index(TABLE_END) + len(TABLE_END) + 1
    return markdown[:start] + parameter_table() + markdown[end:]


def main(root=None) -> int:
    """Rewrite config/ship_ident.yaml and the table in docs/node.md from the definitions."""
    root = Path(root or Path(__file__).resolve().parents[2])  # the repository: ship_ident/online/config.py
    (root / "config" / "ship_ident.yaml").write_text(parameter_file())
    docs = root / "docs" / "node.md"
    docs.write_text(with_table(docs.read_text()))
    print(f"wrote {root / 'config' / 'ship_ident.yaml'} and the parameter table of {docs}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
