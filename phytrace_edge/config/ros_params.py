"""Settings given as ROS parameters: ``-p name:=value`` after ``--ros-args``."""

from __future__ import annotations

import itertools


def ros_parameters(ros_args: list[str]) -> dict[str, str]:
    """``-p name:=value`` pairs of ROS arguments (as ``ros2 run`` and launch files pass
    them after ``--ros-args``); other ROS arguments (remaps, log levels) are rclpy's."""
    params = {}
    for flag, value in itertools.pairwise(ros_args):
        if flag in ("-p", "--param") and ":=" in value:
            name, _, text = value.partition(":=")
            text = text.strip().strip("'\"")
            if text:  # a launch argument left empty is not set
                params[name.strip()] = text
    return params
