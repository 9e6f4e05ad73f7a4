"""The topic table: the ten ROS 2 topics of the reference guide, ``/rosout``, and how
each is read; and ``ExtraTopic``, an entry of ``TOPICS_EXTRA`` (any other topic).

Two flags say how a topic's messages are treated:

- ``every_message``: each message matters (diagnostics, goals, delivery status), so
  what arrives between two sample ticks is accumulated by the builder and a source
  must never thin these topics out. Other topics are state streams (odometry, IMU,
  ...) where only the latest value counts.
- ``latched``: the topic publishes on change (a goal, a delivery state), so its latest
  value stays current without a staleness bound. Every other topic goes stale after
  ``STALE_AFTER_S`` and then leaves the event.
"""

from __future__ import annotations


class TopicSpec:
    """One row of the topic table. ``handler`` names the function that reads the
    topic's messages, as ``module:function`` in ``phytrace_edge.ingest``: the settings
    read this table at every start, so it imports nothing (not the handlers, not
    ``dataclasses``)."""

    __slots__ = (
        "also_types",
        "domains",
        "every_message",
        "handler",
        "latched",
        "name",
        "type_name",
    )

    def __init__(
        self,
        name: str,
        type_name: str,
        handler: str,
        domains: tuple[str, ...],
        every_message: bool = False,
        latched: bool = False,
        also_types: tuple[str, ...] = (),  # other types the handler reads on this topic
    ) -> None:
        self.name, self.type_name, self.handler, self.domains = name, type_name, handler, domains
        self.every_message, self.latched, self.also_types = every_message, latched, also_types

    @property
    def type_names(self) -> tuple[str, ...]:
        return (self.type_name, *self.also_types)


TOPICS: tuple[TopicSpec, ...] = (
    TopicSpec("/odom", "nav_msgs/msg/Odometry", "handlers:handle_odometry", ("location", "motion")),
    TopicSpec(
        "/battery_state",
        "sensor_msgs/msg/BatteryState",
        "handlers:handle_battery_state",
        ("power",),
    ),
    TopicSpec("/scan", "sensor_msgs/msg/LaserScan", "handlers:handle_laser_scan", ("perception",)),
    TopicSpec("/imu/data", "sensor_msgs/msg/Imu", "handlers:handle_imu", ("perception", "motion")),
    TopicSpec(
        "/cmd_vel",
        "geometry_msgs/msg/Twist",
        "handlers:handle_twist",
        ("motion",),
        also_types=("geometry_msgs/msg/TwistStamped",),  # what Jazzy's nav2 publishes
    ),
    TopicSpec(
        "/gps/fix",
        "sensor_msgs/msg/NavSatFix",
        "handlers:handle_nav_sat_fix",
        ("location", "perception"),
    ),
    TopicSpec(
        "/diagnostics",
        "diagnostic_msgs/msg/DiagnosticArray",
        "status:handle_diagnostic_array",
        ("operational",),
        every_message=True,
    ),
    TopicSpec(
        "/goal_pose",
        "geometry_msgs/msg/PoseStamped",
        "handlers:handle_pose_stamped",
        ("navigation",),
        every_message=True,
        latched=True,
    ),
    TopicSpec(
        "/joint_states", "sensor_msgs/msg/JointState", "handlers:handle_joint_state", ("actuators",)
    ),
    TopicSpec(
        "/delivery/status",
        "std_msgs/msg/String",
        "status:handle_delivery_status",
        ("operational", "payload"),
        every_message=True,
        latched=True,
    ),
    TopicSpec(
        "/rosout", "rcl_interfaces/msg/Log", "rosout:handle_log", (), every_message=True
    ),  # ROS logs: log.record events, not a domain
)

TOPIC_BY_NAME = {spec.name: spec for spec in TOPICS}
TOPIC_NAMES = tuple(TOPIC_BY_NAME)

EXTRA_MODES = ("sample", "on_change")


class ExtraTopic:
    """One entry of ``TOPICS_EXTRA``: a topic outside the table, shipped as
    ``telemetry.topic`` events (docs/configuration.md, "Any other topic").

    ``type_name`` may be empty: the input then takes it from the graph or the bag.
    ``mode`` ``sample`` sends the latest message at most ``rate_hz`` times a second;
    ``on_change`` only when its data changed (numbers by more than ``deadband``)."""

    __slots__ = ("deadband", "mode", "name", "rate_hz", "type_name")

    def __init__(
        self,
        name: str,
        type_name: str = "",
        rate_hz: float = 1.0,
        mode: str = "sample",
        deadband: float = 0.0,
    ) -> None:
        self.name, self.type_name, self.rate_hz = name, type_name, rate_hz
        self.mode, self.deadband = mode, deadband

    def __eq__(self, other: object) -> bool:
        return isinstance(other, ExtraTopic) and self.describe() == other.describe()

    def __hash__(self) -> int:
        return hash(self.describe())

    def __repr__(self) -> str:
        return f"ExtraTopic({self.describe()!r})"

    def describe(self) -> str:
        """The entry in TOPICS_EXTRA's text form."""
        text = f"{self.name} rate_hz={self.rate_hz:g} mode={self.mode}"
        if self.type_name:
            text += f" type={self.type_name}"
        return text + (f" deadband={self.deadband:g}" if self.deadband else "")
