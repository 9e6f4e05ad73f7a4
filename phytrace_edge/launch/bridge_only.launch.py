"""phytrace-edge attached to a running robot: ``ros2 launch <this file> name:=value ...``.

    ros2 launch bridge_only.launch.py phycloud_endpoint:=https://api.phycloud.phyware.io/v1 \
        source_id:=my-robot-1 source_type:=amr fleet_id:=my-fleet sample_rate_hz:=10.0

Every argument becomes a ROS parameter of the same name as the setting (docs/configuration.md),
below flags, environment and config file in precedence. Prefer PHYCLOUD_API_KEY in the
environment to phycloud_api_key:=...: process arguments are visible to every user of the robot.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.substitutions import LaunchConfiguration

# the reference guide's launch parameters, with their defaults ("" = not set)
ARGUMENTS = {
    "phycloud_endpoint": ("", "PhyCloud ingestion API base URL"),
    "phycloud_api_key": ("", "API key (prefer the PHYCLOUD_API_KEY environment variable)"),
    "source_id": ("", "unique robot id"),
    "source_type": ("", "delivery_robot, amr, agv, drone, humanoid or arm"),
    "fleet_id": ("", "fleet grouping id"),
    "site_id": ("", "site or facility id"),
    "sample_rate_hz": ("", "UDM events built per second"),
    "batch_size": ("", "events per HTTP request"),
}
BRIDGE_INPUT = "ros"


def bridge_command(bridge_input: str) -> list:
    """``phytrace-edge run`` with every argument passed as ``-p name:=value``."""
    parameters = []
    for name in ARGUMENTS:
        parameters += ["-p", [name, ":=", LaunchConfiguration(name)]]
    return ["phytrace-edge", "run", "--input", bridge_input, "--ros-args", *parameters]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            *(
                DeclareLaunchArgument(name, default_value=default, description=doc)
                for name, (default, doc) in ARGUMENTS.items()
            ),
            ExecuteProcess(cmd=bridge_command(BRIDGE_INPUT), output="screen", sigterm_timeout="20"),
        ]
    )
