"""The mock message classes: the topic table's types, ``rcl_interfaces/msg/Log`` and a
few more that ``TOPICS_EXTRA`` tests use, declared as rosidl_generator_py declares them
(``message_base`` has the field-type rules)."""

from __future__ import annotations

from phytrace_edge.sim.mock_ros.message_base import MESSAGE_TYPES, Message, declare, wire_copy

__all__ = ["Message", "message_type", "wire_copy"]

Time = declare("builtin_interfaces/msg/Time", {"sec": "int32", "nanosec": "uint32"})
Header = declare("std_msgs/msg/Header", {"stamp": "builtin_interfaces/Time", "frame_id": "string"})
String = declare("std_msgs/msg/String", {"data": "string"})
Point = declare("geometry_msgs/msg/Point", {"x": "double", "y": "double", "z": "double"})
Vector3 = declare("geometry_msgs/msg/Vector3", {"x": "double", "y": "double", "z": "double"})
Quaternion = declare(
    "geometry_msgs/msg/Quaternion",
    {"x": "double", "y": "double", "z": "double", "w": "double"},
    _field_defaults={"w": 1.0},
)
Pose = declare(
    "geometry_msgs/msg/Pose",
    {"position": "geometry_msgs/Point", "orientation": "geometry_msgs/Quaternion"},
)
PoseWithCovariance = declare(
    "geometry_msgs/msg/PoseWithCovariance",
    {"pose": "geometry_msgs/Pose", "covariance": "double[36]"},
)
Twist = declare(
    "geometry_msgs/msg/Twist",
    {"linear": "geometry_msgs/Vector3", "angular": "geometry_msgs/Vector3"},
)
TwistWithCovariance = declare(
    "geometry_msgs/msg/TwistWithCovariance",
    {"twist": "geometry_msgs/Twist", "covariance": "double[36]"},
)
PoseStamped = declare(
    "geometry_msgs/msg/PoseStamped", {"header": "std_msgs/Header", "pose": "geometry_msgs/Pose"}
)
TwistStamped = declare(
    "geometry_msgs/msg/TwistStamped",
    {"header": "std_msgs/Header", "twist": "geometry_msgs/Twist"},
)
Odometry = declare(
    "nav_msgs/msg/Odometry",
    {
        "header": "std_msgs/Header",
        "child_frame_id": "string",
        "pose": "geometry_msgs/PoseWithCovariance",
        "twist": "geometry_msgs/TwistWithCovariance",
    },
)
BatteryState = declare(
    "sensor_msgs/msg/BatteryState",
    {
        "header": "std_msgs/Header",
        "voltage": "float",
        "temperature": "float",
        "current": "float",
        "charge": "float",
        "capacity": "float",
        "design_capacity": "float",
        "percentage": "float",
        "power_supply_status": "uint8",
        "power_supply_health": "uint8",
        "power_supply_technology": "uint8",
        "present": "boolean",
        "cell_voltage": "sequence<float>",
        "cell_temperature": "sequence<float>",
        "location": "string",
        "serial_number": "string",
    },
    POWER_SUPPLY_STATUS_UNKNOWN=0,
    POWER_SUPPLY_STATUS_CHARGING=1,
    POWER_SUPPLY_STATUS_DISCHARGING=2,
    POWER_SUPPLY_STATUS_NOT_CHARGING=3,
    POWER_SUPPLY_STATUS_FULL=4,
    POWER_SUPPLY_HEALTH_UNKNOWN=0,
    POWER_SUPPLY_HEALTH_GOOD=1,
    POWER_SUPPLY_HEALTH_OVERHEAT=2,
    POWER_SUPPLY_TECHNOLOGY_LION=2,
)
LaserScan = declare(
    "sensor_msgs/msg/LaserScan",
    {
        "header": "std_msgs/Header",
        "angle_min": "float",
        "angle_max": "float",
        "angle_increment": "float",
        "time_increment": "float",
        "scan_time": "float",
        "range_min": "float",
        "range_max": "float",
        "ranges": "sequence<float>",
        "intensities": "sequence<float>",
    },
)
Imu = declare(
    "sensor_msgs/msg/Imu",
    {
        "header": "std_msgs/Header",
        "orientation": "geometry_msgs/Quaternion",
        "orientation_covariance": "double[9]",
        "angular_velocity": "geometry_msgs/Vector3",
        "angular_velocity_covariance": "double[9]",
        "linear_acceleration": "geometry_msgs/Vector3",
        "linear_acceleration_covariance": "double[9]",
    },
)
NavSatStatus = declare(
    "sensor_msgs/msg/NavSatStatus",
    {"status": "int8", "service": "uint16"},
    STATUS_UNKNOWN=-2,
    STATUS_NO_FIX=-1,
    STATUS_FIX=0,
    STATUS_SBAS_FIX=1,
    STATUS_GBAS_FIX=2,
    SERVICE_GPS=1,
    SERVICE_GLONASS=2,
    SERVICE_COMPASS=4,
    SERVICE_GALILEO=8,
)
NavSatFix = declare(
    "sensor_msgs/msg/NavSatFix",
    {
        "header": "std_msgs/Header",
        "status": "sensor_msgs/NavSatStatus",
        "latitude": "double",
        "longitude": "double",
        "altitude": "double",
        "position_covariance": "double[9]",
        "position_covariance_type": "uint8",
    },
    COVARIANCE_TYPE_UNKNOWN=0,
    COVARIANCE_TYPE_APPROXIMATED=1,
    COVARIANCE_TYPE_DIAGONAL_KNOWN=2,
    COVARIANCE_TYPE_KNOWN=3,
)
JointState = declare(
    "sensor_msgs/msg/JointState",
    {
        "header": "std_msgs/Header",
        "name": "sequence<string>",
        "position": "sequence<double>",
        "velocity": "sequence<double>",
        "effort": "sequence<double>",
    },
)
KeyValue = declare("diagnostic_msgs/msg/KeyValue", {"key": "string", "value": "string"})
DiagnosticStatus = declare(
    "diagnostic_msgs/msg/DiagnosticStatus",
    {
        "level": "octet",
        "name": "string",
        "message": "string",
        "hardware_id": "string",
        "values": "sequence<diagnostic_msgs/KeyValue>",
    },
    OK=b"\x00",
    WARN=b"\x01",
    ERROR=b"\x02",
    STALE=b"\x03",
)
DiagnosticArray = declare(
    "diagnostic_msgs/msg/DiagnosticArray",
    {"header": "std_msgs/Header", "status": "sequence<diagnostic_msgs/DiagnosticStatus>"},
)


Temperature = declare(
    "sensor_msgs/msg/Temperature",
    {"header": "std_msgs/Header", "temperature": "double", "variance": "double"},
)
CompressedImage = declare(
    "sensor_msgs/msg/CompressedImage",
    {"header": "std_msgs/Header", "format": "string", "data": "sequence<uint8>"},
)
Transform = declare(
    "geometry_msgs/msg/Transform",
    {"translation": "geometry_msgs/Vector3", "rotation": "geometry_msgs/Quaternion"},
)
TransformStamped = declare(
    "geometry_msgs/msg/TransformStamped",
    {
        "header": "std_msgs/Header",
        "child_frame_id": "string",
        "transform": "geometry_msgs/Transform",
    },
)
TFMessage = declare(
    "tf2_msgs/msg/TFMessage", {"transforms": "sequence<geometry_msgs/TransformStamped>"}
)
MultiArrayDimension = declare(
    "std_msgs/msg/MultiArrayDimension", {"label": "string", "size": "uint32", "stride": "uint32"}
)
MultiArrayLayout = declare(
    "std_msgs/msg/MultiArrayLayout",
    {"dim": "sequence<std_msgs/MultiArrayDimension>", "data_offset": "uint32"},
)
Float32MultiArray = declare(
    "std_msgs/msg/Float32MultiArray",
    {"layout": "std_msgs/MultiArrayLayout", "data": "sequence<float>"},
)
ByteMultiArray = declare(
    "std_msgs/msg/ByteMultiArray",
    {"layout": "std_msgs/MultiArrayLayout", "data": "sequence<octet>"},
)
Log = declare(
    "rcl_interfaces/msg/Log",
    {
        "stamp": "builtin_interfaces/Time",
        "level": "uint8",
        "name": "string",
        "msg": "string",
        "file": "string",
        "function": "string",
        "line": "uint32",
    },
    DEBUG=10,
    INFO=20,
    WARN=30,
    ERROR=40,
    FATAL=50,
)


def message_type(type_name: str) -> type[Message]:
    """The mock class for a ROS type name such as ``sensor_msgs/msg/Imu``."""
    return MESSAGE_TYPES[type_name]
