"""ROS 2's DDS environment variables, read for the ``dds`` input (a module of its own:
the settings are turned into options on every command's start-up path)."""

from __future__ import annotations

from collections.abc import Mapping

from phytrace_edge.errors import ConfigError


def domain_settings(env: Mapping[str, str]) -> tuple[int, bool]:
    """(domain id, localhost only) from ROS 2's environment variables."""
    raw = (env.get("ROS_DOMAIN_ID") or "0").strip()
    if not raw.isascii() or not raw.isdigit() or int(raw) > 232:
        raise ConfigError(f"ROS_DOMAIN_ID={raw!r}: must be a whole number from 0 to 232")
    localhost = env.get("ROS_LOCALHOST_ONLY") == "1" or (
        env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").upper() == "LOCALHOST"
    )
    return int(raw), localhost
