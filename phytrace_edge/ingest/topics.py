"""The topic table: the ten ROS 2 topics of the product's original description (the
README's topic table) and ``/rosout``, each with its type, handler, UDM domains and how
it is heard; and ``ExtraTopic``, an entry of ``TOPICS_EXTRA`` (any other topic).
Adding a topic is one row here, its handler, its reading in ``readings.py`` and, for a
new domain, that domain's builder in ``builder/assemble.py``; README's topic table is
checked against this one.

Two flags say how a topic's messages are treated:

- ``every_message``: each message matters (diagnostics, goals, delivery status), so
  what arrives between two sample ticks is accumulated by the builder and a source
  must never thin these topics out. Other topics are state streams (odometry, IMU,
  ...) where only the latest value counts.
- ``latched``: the topic publishes on change (a goal, a delivery state), so its latest
  value stays current without a staleness bound. Every other topic goes stale after
  ``STALE_AFTER_S`` and then leaves the event.
"""

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, get_args

from phytrace_edge.ingest import handlers, robot_status, rosout
from phytrace_edge.ingest.readings import Reading

if TYPE_CHECKING:  # the types module costs every command's start: annotations only
    from phytrace_edge.udm.types import TopicMode

Domain = Literal[
    "location",
    "motion",
    "power",
    "operational",
    "navigation",
    "perception",
    "actuators",
    "payload",
]
DOMAINS: tuple[Domain, ...] = get_args(Domain)  # in the order of an event's keys
Handler = Callable[[Any], Reading]


class TopicSpec(NamedTuple):
    """One row of the topic table: the topic, its ROS 2 type, the handler that reads
    its messages, the UDM domains its readings feed (each domain's ``sources`` lists
    the topics that feed it), and how it is heard (``every_message``: reliable and
    every message kept; ``latched``: transient local is asked for when the
    publishers offer it, and the value never goes stale)."""

    name: str
    type_name: str
    handler: Handler
    domains: tuple[Domain, ...]
    every_message: bool = False
    latched: bool = False
    also_types: tuple[str, ...] = ()  # other types the handler reads on this topic

    @property
    def type_names(self) -> tuple[str, ...]:
        return (self.type_name, *self.also_types)


TOPICS: tuple[TopicSpec, ...] = (
    TopicSpec("/odom", "nav_msgs/msg/Odometry", handlers.handle_odometry, ("location", "motion")),
    TopicSpec(
        "/battery_state", "sensor_msgs/msg/BatteryState", handlers.handle_battery_state, ("power",)
    ),
    TopicSpec("/scan", "sensor_msgs/msg/LaserScan", handlers.handle_laser_scan, ("perception",)),
    TopicSpec(
        "/imu/data",
        "sensor_msgs/msg/Imu",
        handlers.handle_imu,
        # the orientation gives location's compass heading; the yaw rate, motion's
        ("location", "motion", "perception"),
    ),
    TopicSpec(
        "/cmd_vel",
        "geometry_msgs/msg/Twist",
        handlers.handle_twist,
        ("motion",),
        also_types=("geometry_msgs/msg/TwistStamped",),  # what Jazzy's nav2 publishes
    ),
    TopicSpec(
        "/gps/fix",
        "sensor_msgs/msg/NavSatFix",
        handlers.handle_nav_sat_fix,
        ("location", "perception"),
    ),
    TopicSpec(
        "/diagnostics",
        "diagnostic_msgs/msg/DiagnosticArray",
        robot_status.handle_diagnostic_array,
        ("operational",),
        every_message=True,
    ),
    TopicSpec(
        "/goal_pose",
        "geometry_msgs/msg/PoseStamped",
        handlers.handle_pose_stamped,
        ("navigation",),
        every_message=True,
        latched=True,
    ),
    TopicSpec(
        "/joint_states", "sensor_msgs/msg/JointState", handlers.handle_joint_state, ("actuators",)
    ),
    TopicSpec(
        "/delivery/status",
        "std_msgs/msg/String",
        robot_status.handle_delivery_status,
        ("operational", "payload"),
        every_message=True,
        latched=True,
    ),
    # ROS logs: log.record events of their own, not a domain
    TopicSpec("/rosout", "rcl_interfaces/msg/Log", rosout.handle_log, (), every_message=True),
)

TOPIC_BY_NAME = {spec.name: spec for spec in TOPICS}
TOPIC_NAMES = tuple(TOPIC_BY_NAME)

EXTRA_MODES: "tuple[TopicMode, ...]" = ("sample", "on_change")  # udm.types.TopicMode


class ExtraTopic(NamedTuple):
    """One entry of ``TOPICS_EXTRA``: a topic outside the table, shipped as
    ``telemetry.topic`` events (docs/configuration.md, "Any other topic").

    ``type_name`` may be empty: the input then takes it from the graph or the bag.
    ``mode`` ``sample`` sends the latest message at most ``rate_hz`` times a second;
    ``on_change`` only when its data changed (numbers by more than ``deadband``)."""

    name: str
    type_name: str = ""
    rate_hz: float = 1.0
    mode: "TopicMode" = "sample"
    deadband: float = 0.0

    def describe(self) -> str:
        """The entry in TOPICS_EXTRA's text form."""
        text = f"{self.name} rate_hz={self.rate_hz:g} mode={self.mode}"
        if self.type_name:
            text += f" type={self.type_name}"
        return text + (f" deadband={self.deadband:g}" if self.deadband else "")
