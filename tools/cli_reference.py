"""Write docs/cli.md, the CLI reference, from the commands' own --help.

    python3 tools/cli_reference.py           # rewrite docs/cli.md
    python3 tools/cli_reference.py --check   # exit 1 if docs/cli.md is stale

tests/unit/test_cli_docs.py runs the check, so the reference cannot drift from the code.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from phytrace_edge.cli import COMMANDS, build_parser, command_parser  # noqa: E402

TARGET = ROOT / "docs" / "cli.md"
WIDTH = 100
HEADER = """# CLI reference

Generated from the commands' `--help` by `python3 tools/cli_reference.py`; do not edit by
hand. Every setting flag is also an environment variable and a TOML key
([configuration.md](configuration.md)); exit codes are in
[operations.md](operations.md#exit-codes).
"""


def fixed_width(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    parser.formatter_class = lambda prog: argparse.HelpFormatter(prog, width=WIDTH)
    return parser


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:  # argparse keeps its subparsers here, and only here
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def normalised(text: str) -> str:
    """Help text the same on every Python: 3.10 says "optional arguments"."""
    return text.replace("optional arguments:", "options:")


def reference() -> str:
    parser = fixed_width(build_parser())
    parts = [HEADER, "## phytrace-edge\n", "```text", normalised(parser.format_help()), "```\n"]
    for name in COMMANDS:
        command = command_parser(name)
        parts += [f"## phytrace-edge {name}\n", "```text"]
        parts += [normalised(fixed_width(command).format_help()), "```\n"]
    return "\n".join(parts)


def main() -> int:
    check = "--check" in sys.argv[1:]
    text = reference()
    if check:
        if TARGET.read_text("utf-8") != text:
            print(f"{TARGET} is stale: run python3 tools/cli_reference.py", file=sys.stderr)
            return 1
        return 0
    TARGET.write_text(text, "utf-8")
    print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
