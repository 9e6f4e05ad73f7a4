"""The ``phytrace-edge`` command: thin subcommands over the library.

Each command parses its arguments, loads settings, calls one function and turns
project errors into one line on stderr and a non-zero exit (2 for bad input), never a
traceback.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

import orjson

from phytrace_edge import __version__
from phytrace_edge.config import (
    LoadedSettings,
    Secret,
    format_bytes,
    setting_infos,
    settings_from_environment,
)
from phytrace_edge.errors import PhytraceError

EXIT_BAD_INPUT = 2
Command = Callable[[argparse.Namespace, LoadedSettings], int]


def _setting_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("settings (each also an environment variable)")
    group.add_argument("--config", metavar="PATH", help="TOML config file (or PHYTRACE_CONFIG)")
    for info in setting_infos():
        group.add_argument(
            info.flag, dest=f"setting_{info.key}", metavar="VALUE", help=f"{info.doc} [{info.env}]"
        )


def _flags(args: argparse.Namespace) -> dict[str, Any]:
    prefix = "setting_"
    return {k[len(prefix) :]: v for k, v in vars(args).items() if k.startswith(prefix)}


def shown_value(key: str, value: Any) -> str:
    """A setting's value as ``config`` prints it (the API key redacted)."""
    if isinstance(value, Secret):
        return str(value) or "(empty)"
    if value is None:
        return "(none)"
    if key.endswith("_bytes") and isinstance(value, int):
        return f"{value} ({format_bytes(value)})"
    if isinstance(value, (dict, frozenset)):
        items = value.items() if isinstance(value, dict) else ((v, None) for v in sorted(value))
        return ",".join(k if v is None else f"{k}={v}" for k, v in items) or "(none)"
    return str(value)


def cmd_config(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Print the effective settings and where each came from."""
    rows = [
        (
            info.env,
            shown_value(info.key, getattr(loaded.settings, info.key)),
            loaded.origins[info.key],
        )
        for info in setting_infos()
    ]
    if args.json:
        document = {env: {"value": value, "source": origin} for env, value, origin in rows}
        sys.stdout.write(orjson.dumps(document, option=orjson.OPT_INDENT_2).decode() + "\n")
        return 0
    width = max(len(env) for env, _, _ in rows)
    value_width = min(48, max(len(value) for _, value, _ in rows))
    for env, value, origin in rows:
        print(f"{env:<{width}}  {value:<{value_width}}  {origin}")
    return 0


def cmd_sim(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Run the simulated delivery robot through the bridge and print the stats."""
    from phytrace_edge.sim.runner import run_simulation

    stats = run_simulation(
        args.ticks, settings=loaded.settings, seed=args.seed, realtime=args.realtime
    )
    sys.stdout.write(orjson.dumps(stats, option=orjson.OPT_INDENT_2).decode() + "\n")
    return 0 if stats["events_failed"] == 0 else 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="phytrace-edge",
        description="PhyTrace edge bridge: ROS 2 topics -> UDM events -> queue -> PhyCloud.",
    )
    parser.add_argument("--version", action="version", version=f"phytrace-edge {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    config = commands.add_parser("config", help="print the effective settings and their sources")
    config.add_argument("--json", action="store_true", help="print JSON instead of a table")
    config.set_defaults(handler=cmd_config)

    sim = commands.add_parser("sim", help="run the simulated delivery robot through the bridge")
    sim.add_argument("--ticks", type=int, default=100, help="robot cycles at 10 Hz (default 100)")
    sim.add_argument("--seed", type=int, default=0, help="random seed of the simulated world")
    sim.add_argument("--realtime", action="store_true", help="run at wall-clock pace")
    sim.set_defaults(handler=cmd_sim)

    for command in (config, sim):
        _setting_flags(command)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``phytrace-edge`` console script."""
    args = build_parser().parse_args(argv)
    try:
        loaded = settings_from_environment(_flags(args), config_path=args.config)
        logging.basicConfig(
            level=loaded.settings.log_level,
            format="%(asctime)s %(levelname)s %(name)s: %(message)s",
        )
        handler: Command = args.handler
        return handler(args, loaded)
    except PhytraceError as exc:
        print(f"phytrace-edge: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # the reader went away (`| head`): stop quietly, and keep the interpreter's
        # final flush from raising again at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
