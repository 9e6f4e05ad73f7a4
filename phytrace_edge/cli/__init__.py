"""The ``phytrace-edge`` command: one thin module per subcommand.

Each command parses its arguments, calls one function and turns project errors into
one line on stderr and the error's exit code (``errors.py`` lists them), never a
traceback. Commands import what they use inside their ``run``, so ``--help`` and
``status`` start fast.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from collections.abc import Sequence
from typing import Any

from phytrace_edge._version import __version__
from phytrace_edge.cli import common
from phytrace_edge.config import ros_parameters, settings_from_environment
from phytrace_edge.errors import EXIT_INTERRUPTED, EXIT_OK, PhytraceError

# command -> its module, imported when used: one run of the CLI needs one of them
COMMANDS = {
    name: f"phytrace_edge.cli.{name.replace('-', '_')}"
    for name in (
        "run",
        "status",
        "drain",
        "config",
        "sim",
        "dead-letters",
        "stub",
        "export",
        "inspect",
        "mark",
    )
} | {"import": "phytrace_edge.cli.import_files"}  # `import` is a Python keyword
DESCRIPTION = "PhyTrace edge bridge: ROS 2 topics -> UDM events -> queue -> PhyCloud."


def _configure(parser: argparse.ArgumentParser, command: Any) -> argparse.ArgumentParser:
    command.configure(parser)
    parser.set_defaults(handler=command.run, logs=getattr(command, "LOGS", True))
    if getattr(command, "TAKES_SETTINGS", True):
        common.add_setting_flags(parser)
    return parser


def command_module(name: str) -> Any:
    return importlib.import_module(COMMANDS[name])


def command_parser(name: str) -> argparse.ArgumentParser:
    """The parser of one command, as ``phytrace-edge NAME`` (all that one run needs)."""
    command = command_module(name)
    parser = common.Parser(prog=f"phytrace-edge {name}", description=command.HELP)
    return _configure(parser, command)


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``phytrace-edge`` with every command (for --help and the docs)."""
    parser = common.Parser(prog="phytrace-edge", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"phytrace-edge {__version__}")
    commands = parser.add_subparsers(
        dest="command", required=True, metavar="COMMAND", parser_class=common.Parser
    )
    for name in COMMANDS:
        command = command_module(name)
        _configure(commands.add_parser(name, help=command.HELP, description=command.HELP), command)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``phytrace-edge`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    # everything after --ros-args is for ROS: parameters here, the rest for rclpy
    split = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    if argv and argv[0] in COMMANDS:  # the usual case: build only what this run uses
        args = command_parser(argv[0]).parse_args(argv[1:split])
    else:  # --help, --version or a mistake: the full parser answers (and exits)
        args = build_parser().parse_args(argv[:split])
    args.ros_args = argv[split + 1 :]
    try:
        loaded = settings_from_environment(
            common.setting_flags(args),
            os.environ,
            config_path=getattr(args, "config", None),
            ros_params=ros_parameters(args.ros_args),
            env_file=getattr(args, "env_file", None),
        )
        if args.logs:
            from phytrace_edge.runtime.options import configure_logging

            configure_logging(loaded.settings, os.environ)
        for warning in loaded.warnings:
            if args.logs:
                logging.getLogger("phytrace_edge").warning(warning)
            else:
                sys.stderr.write(f"phytrace-edge: warning: {warning}\n")
        code: int = args.handler(args, loaded)
        sys.stdout.flush()  # here, so that a reader gone away is handled below
        return code
    except PhytraceError as exc:
        common.error(str(exc))
        return exc.exit_code
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader went away (`| head`): stop quietly, and keep the interpreter's
        # final flush from raising again at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
