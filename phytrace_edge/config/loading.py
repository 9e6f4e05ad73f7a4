"""Loading the settings from their sources, highest first: command-line flag,
environment variable, config file (TOML), ROS parameter, default.

``load_settings`` is a pure function from those sources to a frozen ``Settings``; the
CLI calls ``settings_from_environment`` at its edge, and only the runtime's wiring
reads the result. An empty environment variable counts as unset, because compose
files pass ``${FLEET_ID}`` through as an empty string when the operator did not set it.
"""

import os
import stat
import sys
from collections.abc import Mapping
from typing import Any, NamedTuple

from phytrace_edge.config.settings import Setting, Settings, setting_infos
from phytrace_edge.errors import ConfigError
from phytrace_edge.redact import redact_url
from phytrace_edge.units import format_bytes

CONFIG_FILE_MAX_BYTES = 1024 * 1024
SHOWN_MAX_CHARS = 60


class LoadedSettings(NamedTuple):
    """Settings plus where each value came from (``default``, ``env NAME``, ...)."""

    settings: Settings
    origins: dict[str, str]
    warnings: tuple[str, ...] = ()  # for the log, once it is set up


def _shown(info: Setting, raw: Any) -> str:
    """A value as an error message quotes it: the API key never, and nothing long."""
    if info.key == "phycloud_api_key":
        return "'***'"
    if isinstance(raw, str) and "@" in raw:  # a URL's user:password, scheme or not
        raw = redact_url(raw) if "://" in raw else redact_url("//" + raw)[2:]
    text = ascii(raw)
    return text if len(text) <= SHOWN_MAX_CHARS else text[:SHOWN_MAX_CHARS] + "...'"


def load_settings(
    flags: Mapping[str, Any] | None = None,
    env: Mapping[str, str] | None = None,
    config_file: Mapping[str, Any] | None = None,
    ros_params: Mapping[str, Any] | None = None,
    file_label: str = "file",
) -> LoadedSettings:
    """Resolve every setting from its sources (flags > env > file > ROS param > default).

    ``flags``, ``config_file`` and ``ros_params`` are keyed by the lower-case name; a
    flag whose value is None was not given. Raises ``ConfigError`` naming the setting,
    the value and what is allowed.
    """
    flags, env = flags or {}, env or {}
    config_file, ros_params = config_file or {}, ros_params or {}
    known = {info.key for info in setting_infos()}
    for key in config_file:
        if key not in known:
            raise ConfigError(f"{file_label}: unknown setting {key!r}")

    values: dict[str, Any] = {}
    origins: dict[str, str] = {}
    for info in setting_infos():
        raw, origin, name = _pick(info, flags, env, config_file, ros_params, file_label)
        if origin == "default":
            values[info.key] = info.default
        else:
            try:
                values[info.key] = info.parse(raw)
            except ValueError as exc:
                raise ConfigError(f"{name}={_shown(info, raw)}: must be {exc}") from None
        origins[info.key] = origin

    settings = Settings(**values)
    if settings.retry_max_s < settings.retry_min_s:
        raise ConfigError(
            f"RETRY_MAX_S={settings.retry_max_s:g}: must be >= RETRY_MIN_S "
            f"({settings.retry_min_s:g})"
        )
    if settings.queue_path is None:
        settings = settings.replace(queue_path=os.path.join(default_state_dir(env), "queue.db"))
    return LoadedSettings(settings, origins)


def _pick(
    info: Setting,
    flags: Mapping[str, Any],
    env: Mapping[str, str],
    config_file: Mapping[str, Any],
    ros_params: Mapping[str, Any],
    file_label: str,
) -> tuple[Any, str, str]:
    """The raw value of one setting, its origin label and the name to blame in errors."""
    if flags.get(info.key) is not None:
        return flags[info.key], f"flag {info.flag}", info.flag
    for name in (info.env, *info.aliases):
        if env.get(name, "").strip():
            return env[name], f"env {name}", name
    if info.key in config_file:
        return config_file[info.key], file_label, f"{file_label}: {info.key}"
    if info.key in ros_params:
        return ros_params[info.key], "ros param", f"ros param {info.key}"
    return None, "default", info.env


def read_config_file(path: str) -> dict[str, Any]:
    """Parse a TOML config file into a flat {key: value} table."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - exercised on 3.10 only
        import tomli as tomllib
    data = _read_small_file(path, "config file", CONFIG_FILE_MAX_BYTES)
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ConfigError(f"config file {path}: not UTF-8 text (byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config file {path}: not valid TOML ({exc})") from None


def _read_small_file(path: str, what: str, max_bytes: int) -> bytes:
    """The bytes of a settings file (``what`` names it in errors): a regular file of at
    most ``max_bytes``, or a one-line ``ConfigError``."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            raise ConfigError(f"{what} {path}: not a regular file")
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except FileNotFoundError:
        raise ConfigError(f"{what} {path}: not found") from None
    except OSError as exc:
        raise ConfigError(f"{what} {path}: cannot read ({exc.strerror})") from None
    if len(data) > max_bytes:
        limit = format_bytes(max_bytes)
        raise ConfigError(f"{what} {path}: larger than {limit} - is it the right file?")
    return data


def default_state_dir(env: Mapping[str, str]) -> str:
    """Where the queue lives when QUEUE_PATH is not set.

    systemd's ``StateDirectory=`` sets ``$STATE_DIRECTORY`` (a colon-separated list);
    the container image sets ``PHYTRACE_STATE_DIR=/var/lib/phytrace-edge`` on its volume;
    otherwise the per-user XDG state directory.
    """
    if env.get("STATE_DIRECTORY"):
        return env["STATE_DIRECTORY"].split(":")[0]
    if env.get("PHYTRACE_STATE_DIR"):
        return env["PHYTRACE_STATE_DIR"]
    home = env.get("HOME", "~")
    base = env.get("XDG_STATE_HOME") or os.path.join(home, ".local", "state")
    return os.path.join(os.path.expanduser(base), "phytrace-edge")


ENV_FILE_MAX_BYTES = 64 * 1024


def read_env_file(path: str) -> dict[str, str]:
    """A systemd ``EnvironmentFile`` (``KEY=VALUE`` lines; ``#`` and ``;`` comments;
    a value may be quoted) as a dict: the service's settings, for a command run beside
    the service (``status --env-file /etc/phytrace-edge/phytrace-edge.env``)."""
    data = _read_small_file(path, "env file", ENV_FILE_MAX_BYTES)
    values = {}
    for number, raw in enumerate(data.decode("utf-8", "replace").splitlines(), start=1):
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        key, equals, value = line.partition("=")
        key, value = key.strip(), value.strip()
        if not equals or not key.isidentifier() or not key.isascii():
            raise ConfigError(f"env file {path}: line {number} is not KEY=VALUE")
        if len(value) >= 2 and value[0] == value[-1] and value[0] in "\"'":
            value = value[1:-1]
        values[key] = value
    return values


def settings_from_environment(
    flags: Mapping[str, Any] | None,
    env: Mapping[str, str],
    config_path: str | None = None,
    ros_params: Mapping[str, Any] | None = None,
    env_file: str | None = None,
) -> LoadedSettings:
    """Load settings the way the CLI does: flags, the process environment ``env`` over
    the env file named by ``--env-file`` or ``PHYTRACE_ENV_FILE``, the config file named
    by ``--config`` or ``PHYTRACE_CONFIG``, and ROS parameters."""
    env_file = env_file or env.get("PHYTRACE_ENV_FILE") or None
    if env_file:
        env = {**read_env_file(env_file), **env}
    path = config_path or env.get("PHYTRACE_CONFIG") or None
    file_values = read_config_file(path) if path else {}
    loaded = load_settings(flags, env, file_values, ros_params, file_label=f"config file {path}")
    if path and file_values.get("phycloud_api_key"):
        return loaded._replace(warnings=_readable_by_others(path))
    return loaded


def _readable_by_others(path: str) -> tuple[str, ...]:
    """A warning when the config file holding the API key is readable by other users."""
    try:
        mode = stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        return ()
    if not mode & 0o044:
        return ()
    return (
        f"config file {path} holds the API key and is readable by other users (mode "
        f"{mode:04o}): chmod 600 {path}, or move the key to PHYCLOUD_API_KEY_FILE",
    )
