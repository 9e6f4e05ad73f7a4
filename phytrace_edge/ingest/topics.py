"""The topic table: the ten ROS 2 topics of the reference guide and how each is read.

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
)

TOPIC_BY_NAME = {spec.name: spec for spec in TOPICS}
TOPIC_NAMES = tuple(TOPIC_BY_NAME)
