"""Settings given as ROS parameters, after ``--ros-args``: ``-p name:=value`` and
``--params-file FILE``, applied in the order given (a later one wins), as rcl does.

A params file is rcl's YAML: ``<node>: {ros__parameters: {name: value}}``, where the
node is ``phytrace_edge`` (``/phytrace_edge``, or a namespace's) or ``/**`` for every
node. PyYAML is imported only for a params file (it comes with ROS 2's Python).
"""

from __future__ import annotations

import itertools
from typing import Any

from phytrace_edge.errors import ConfigError

NODE_NAME = "phytrace_edge"  # the bridge's node (ingest.sources.base.NODE_NAME)


def ros_parameters(ros_args: list[str]) -> dict[str, Any]:
    """The settings the ROS arguments give; other ROS arguments (remaps, log levels)
    are rclpy's. Raises ``ConfigError`` for a params file that cannot be read."""
    params: dict[str, Any] = {}
    for flag, value in itertools.pairwise(ros_args):
        if flag in ("-p", "--param") and ":=" in value:
            name, _, text = value.partition(":=")
            text = text.strip().strip("'\"")
            if text:  # a launch argument left empty is not set
                params[name.strip()] = text
        elif flag == "--params-file":
            params.update(params_file(value))
    return params


def params_file(path: str) -> dict[str, Any]:
    """The parameters an rcl params file gives the bridge's node."""
    try:
        import yaml
    except ImportError:
        raise ConfigError(
            f"--params-file {path}: reading it needs PyYAML (pip install pyyaml)"
        ) from None
    try:
        with open(path, encoding="utf-8") as handle:
            document = yaml.safe_load(handle)
    except OSError as exc:
        raise ConfigError(f"--params-file {path}: cannot read ({exc.strerror})") from None
    except yaml.YAMLError as exc:
        reason = str(exc).splitlines()[0]
        raise ConfigError(f"--params-file {path}: not valid YAML ({reason})") from None
    if not isinstance(document, dict):
        raise ConfigError(f"--params-file {path}: not a mapping of node names to parameters")
    params: dict[str, Any] = {}
    for node, section in document.items():
        name = str(node).rsplit("/", 1)[-1]
        if name not in ("**", NODE_NAME):
            continue
        values = section.get("ros__parameters") if isinstance(section, dict) else None
        if not isinstance(values, dict):
            raise ConfigError(f"--params-file {path}: {node} has no ros__parameters mapping")
        params.update(values)
    return params
