"""The CLI and its docs cannot drift apart (in the manner of sqlite-utils' test_docs):
the reference is generated from --help, every command has help text, and every
command is in the README's table."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from phytrace_edge.cli import build_parser, command_parser

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))

from cli_reference import subcommands  # noqa: E402

COMMANDS = subcommands(build_parser())


def test_the_cli_reference_is_generated_from_the_current_help() -> None:
    result = subprocess.run(
        [sys.executable, "tools/cli_reference.py", "--check"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_and_option_has_help_text(name: str) -> None:
    parser = build_parser()
    choices = next(
        a for a in parser._actions if isinstance(a, argparse._SubParsersAction)
    )._choices_actions
    assert any(a.dest == name and a.help for a in choices), f"{name} has no help line"
    for action in command_parser(name)._actions:
        if action.option_strings and action.dest != "help":
            assert action.help, f"{name} {action.option_strings} has no help text"


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_is_in_the_readme_and_the_reference(name: str) -> None:
    assert f"`phytrace-edge {name}" in (ROOT / "README.md").read_text()
    assert f"## phytrace-edge {name}\n" in (ROOT / "docs" / "cli.md").read_text()
