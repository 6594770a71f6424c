"""``ship-ident play BAG``: publish a bag's input topics live, with ``/clock`` (stand-in for ros2 bag play).

Each sample goes out as std_msgs/Float64 on its topic (an Imu bag's heading
and yaw rate on the Float64 heading and yaw-rate topics), preceded by a
rosgraph_msgs/Clock with its bag time, at ``--rate`` times real time. Nodes
started with ``use_sim_time:=true`` follow the bag's clock. ``--loop``
repeats the bag with the clock running on (no jump back).
"""

from __future__ import annotations

import sys
import time

from ..io.files import DEFAULT_TOPICS, Topics, read_samples
from . import SUMMARIES
from .common import add_data_args, topics_from_args


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("play", help=SUMMARIES["play"], description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("bag", metavar="BAG", help="rosbag2 directory, .mcap file or CSV file")
    add_data_args(parser)
    parser.add_argument(
        "--rate",
        type=float,
        default=1.0,
        metavar="R",
        help="playback speed in multiples of real time (default %(default)s)",
    )
    parser.add_argument("--loop", action="store_true", help="play the bag again and again")
    parser.add_argument(
        "--wait-for-subscribers",
        type=float,
        default=0.0,
        metavar="S",
        help="wait up to S s for a subscriber on the rudder topic before playing",
    )
    parser.set_defaults(func=run)


class Player:
    """Publishers of the input topics and of /clock on an rclpy node."""

    def __init__(self, node, topics: Topics = DEFAULT_TOPICS, depth: int = 100):
        from rclpy.qos import QoSProfile
        from rosgraph_msgs.msg import Clock
        from std_msgs.msg import Float64

        self._Float64, self._Clock = Float64, Clock
        self.node = node
        qos = QoSProfile(depth=depth)
        self.publishers = {
            role: node.create_publisher(Float64, getattr(topics, role), qos)
            for role in ("rudder", "heading", "yaw_rate", "speed")
        }
        self.clock = node.create_publisher(Clock, "/clock", qos)
        self.clock_time = None  # s, the newest /clock published

    def publish_clock(self, time_s: float) -> None:
        msg = self._Clock()
        msg.clock.sec = int(time_s // 1)
        msg.clock.nanosec = int(round((time_s - msg.clock.sec) * 1e9)) % 1_000_000_000
        self.clock.publish(msg)
        self.clock_time = time_s

    def republish_clock(self) -> None:
        """Publish the newest /clock again (none before the first). A node takes /clock best effort
        (rclpy's time source): one lost on a loaded machine is not sent again by DDS, and while the play
        is held nothing newer follows it, so the node's clock would stay short of the refit it waits for."""
        if self.clock_time is not None:
            self.publish_clock(self.clock_time)

    def publish(self, role: str, value: float) -> None:
        self.publishers[role].publish(self._Float64(data=float(value)))

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for someone to subscribe to the rudder topic."""
        deadline = time.monotonic() + timeout
        while self.publishers["rudder"].get_subscription_count() == 0:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True

    def play(self, samples, rate: float = 1.0, loop: bool = False, hold=None) -> None:
        """Publish time-ordered samples at ``rate`` x real time, /clock before each stamp, half-way
        from the previous one: /clock and the inputs are separate topics, which DDS does not order
        between them; published together, an input overtaking its clock message was stamped with
        the previous reading by a node stamping on arrival, and rejected as a duplicate.

        ``hold(stamp)``, when given, is called before each new /clock stamp (s) and may block, e.g.
        until a node has caught up with the clock: the play then goes on at ``rate`` from where it
        was held, so a slow subscriber slows the play instead of falling behind it."""
        if rate <= 0:
            raise ValueError(f"--rate must be > 0, got {rate}")
        start, stop = samples[0].time, samples[-1].time
        period = stop - start + (samples[1].time - start if len(samples) > 1 else 0.1)
        offset = 0.0
        wall0 = time.monotonic()

        def wait_until(stamp: float) -> None:
            delay = wall0 + (stamp - start) / rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)

        clock = None
        while True:
            for sample in samples:
                stamp = sample.time + offset
                if stamp != clock:
                    if hold is not None:
                        held = time.monotonic()
                        hold(stamp)
                        wall0 += time.monotonic() - held
                    wait_until(stamp if clock is None else (clock + stamp) / 2)
                    self.publish_clock(stamp)
                    wait_until(stamp)
                    clock = stamp
                self.publish(sample.role, sample.value)
            if not loop:
                return
            offset += period


def run(args) -> int:
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    topics = topics_from_args(args)
    samples = read_samples(args.bag, topics)
    if not samples:
        raise ValueError(f"{args.bag} holds no input samples; check the topic names")
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("ship_ident_play")
    try:
        player = Player(node, topics)
        if args.wait_for_subscribers and not player.wait_for_subscribers(args.wait_for_subscribers):
            print(
                f"ship-ident play: no subscriber on {topics.rudder} after "
                f"{args.wait_for_subscribers:g} s; playing anyway",
                file=sys.stderr,
            )
        player.play(samples, args.rate, args.loop)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
