"""What each handler hands the builder: one ``TypedDict`` per topic of the table.

Readings are already in UDM units and shapes (docs/udm.md). Every key is optional:
a handler leaves out what a message does not carry (unset, NaN, out of range), so a
reader uses ``.get``. The builder reads these names and mypy checks them: a key
renamed here and not there fails the type check, not production; a handler that
writes a key not declared here fails ``tests/unit/test_topic_table.py``
(``test_a_handler_writes_only_what_its_reading_declares``).

``Readings`` is the latest reading of every table topic by topic name, the form the
event is assembled from (``builder/assemble.py``).
"""

# No `from __future__ import annotations` here: TypedDict would compile each string
# annotation at import, a millisecond on the start-up path of `status`.
from typing import Any, TypedDict


class Checked(TypedDict, total=False):
    """Fields a handler left out for a wrong type, and how many strings it had to
    repair (``ingest/safe_text.py``): the dispatcher counts and removes both before
    the reading reaches the builder."""

    rejected_fields: list[str]
    text_repaired: int


class Stamped(Checked, total=False):
    """What every reading of a message with a ``std_msgs/Header`` may carry."""

    stamp_ns: int  # the header stamp, nanoseconds since its clock's epoch
    frame_id: str


class OdometryReading(Stamped, total=False):
    local: dict[str, Any]  # x_m, y_m, z_m, yaw_deg, coordinate_frame
    linear_velocity: dict[str, float]  # x_mps, y_mps, z_mps
    angular_velocity: dict[str, float]  # roll_dps, pitch_dps, yaw_dps


class BatteryReading(Stamped, total=False):
    battery: dict[str, Any]
    charging: dict[str, Any]  # is_charging, status
    power_state: str


class LaserScanReading(Stamped, total=False):
    lidar: dict[str, Any]


class Orientation(TypedDict):
    roll: float
    pitch: float
    yaw: float  # degrees, in the IMU's world frame (ENU)


class ImuFields(TypedDict, total=False):
    orientation_deg: Orientation
    angular_velocity_dps: dict[str, float]  # x, y, z
    linear_acceleration_mps2: dict[str, float]


class ImuReading(Stamped, total=False):
    imu: ImuFields


class TwistReading(Stamped, total=False):
    commanded_velocity: dict[str, float]


class GpsFields(TypedDict, total=False):
    fix_type: str
    latitude: float
    longitude: float
    altitude_m: float
    horizontal_accuracy_m: float


class NavSatFixReading(Stamped, total=False):
    gps: GpsFields


class GoalReading(Stamped, total=False):
    goal: dict[str, Any]  # frame_id, x_m, y_m, z_m, yaw_deg


class JointStateReading(Stamped, total=False):
    joints: list[dict[str, Any]]


class DiagnosticStatusFields(TypedDict, total=False):
    name: str
    level: str  # ok, warn, error, stale, unknown
    message: str
    hardware_id: str


class DiagnosticsReading(Stamped, total=False):
    statuses: list[DiagnosticStatusFields]


class DeliveryStatusReading(Stamped, total=False):
    state: str
    task: dict[str, str]
    payload: dict[str, str]


class LogReading(Checked, total=False):
    level: str
    logger: str
    message: str
    file: str
    function: str
    line: int
    stamp_ns: int


Reading = (
    OdometryReading
    | BatteryReading
    | LaserScanReading
    | ImuReading
    | TwistReading
    | NavSatFixReading
    | GoalReading
    | JointStateReading
    | DiagnosticsReading
    | DeliveryStatusReading
    | LogReading
)

# The latest reading per topic, keyed by the table's topic names (ingest/topics.py).
Readings = TypedDict(
    "Readings",
    {
        "/odom": OdometryReading,
        "/battery_state": BatteryReading,
        "/scan": LaserScanReading,
        "/imu/data": ImuReading,
        "/cmd_vel": TwistReading,
        "/gps/fix": NavSatFixReading,
        "/diagnostics": DiagnosticsReading,
        "/goal_pose": GoalReading,
        "/joint_states": JointStateReading,
        "/delivery/status": DeliveryStatusReading,
    },
    total=False,
)
