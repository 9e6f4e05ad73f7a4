"""Configuration: every setting has one name, one default, one validation rule and one
doc line (``settings``), parsed by pure functions (``parsers``) from its sources
(``loading``, ``ros_params``). Only the CLI and ``runtime/wiring.py`` read it."""

from phytrace_edge.config.loading import (
    LoadedSettings,
    default_state_dir,
    load_settings,
    read_config_file,
    settings_from_environment,
)
from phytrace_edge.config.ros_params import ros_parameters
from phytrace_edge.config.settings import SOURCE_TYPES, Setting, Settings, setting_infos

__all__ = [
    "SOURCE_TYPES",
    "LoadedSettings",
    "Setting",
    "Settings",
    "default_state_dir",
    "load_settings",
    "read_config_file",
    "ros_parameters",
    "setting_infos",
    "settings_from_environment",
]
