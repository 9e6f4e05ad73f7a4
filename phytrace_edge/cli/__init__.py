"""The ``phytrace-edge`` command: one thin module per subcommand.

Each command parses its arguments, calls one function and turns project errors into
one line on stderr and the error's exit code (``errors.py`` lists them), never a
traceback. Commands import what they use inside their ``run``, so ``--help`` and
``status`` start fast.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from phytrace_edge import __version__
from phytrace_edge.cli import common, config, dead_letters, drain, run, sim, status, stub
from phytrace_edge.config import ros_parameters, settings_from_environment
from phytrace_edge.errors import EXIT_INTERRUPTED, EXIT_OK, PhytraceError
from phytrace_edge.runtime import wiring

COMMANDS = (run, status, drain, config, sim, dead_letters, stub)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="phytrace-edge",
        description="PhyTrace edge bridge: ROS 2 topics -> UDM events -> queue -> PhyCloud.",
    )
    parser.add_argument("--version", action="version", version=f"phytrace-edge {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        sub = command.add_parser(commands)
        sub.set_defaults(handler=command.run)
        if getattr(command, "TAKES_SETTINGS", True):
            common.add_setting_flags(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``phytrace-edge`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    # everything after --ros-args is for ROS: parameters here, the rest for rclpy
    split = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    args = build_parser().parse_args(argv[:split])
    args.ros_args = argv[split + 1 :]
    try:
        loaded = settings_from_environment(
            common.setting_flags(args),
            os.environ,
            config_path=getattr(args, "config", None),
            ros_params=ros_parameters(args.ros_args),
        )
        wiring.configure_logging(loaded.settings)
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
