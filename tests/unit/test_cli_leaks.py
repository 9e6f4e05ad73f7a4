"""What the command line prints never shows a secret typed or configured: a mistyped
option's value (argparse would quote it into the journal), a URL's password (config)."""

from __future__ import annotations

import json

import pytest

from phytrace_edge.cli.common import without_values
from tests.processes import run_cli

KEY = "phk_live_Zq8v2K9x7Lw3"


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (
            ["run", "--phycloud-apikey", KEY],
            "phytrace-edge run: error: unrecognized arguments: --phycloud-apikey *** "
            "(see phytrace-edge run --help)",
        ),
        (
            ["run", f"--phycloud-apikey={KEY}"],
            "phytrace-edge run: error: unrecognized arguments: --phycloud-apikey=*** "
            "(see phytrace-edge run --help)",
        ),
        (
            ["run", f"-x{KEY}", KEY, "--input", "sim"],
            "phytrace-edge run: error: unrecognized arguments: -x*** *** "
            "(see phytrace-edge run --help)",
        ),
        (  # a prefix of two options: argparse quotes the whole word
            ["run", f"--phycloud={KEY}"],
            "phytrace-edge run: error: ambiguous option: --phycloud=*** could match ",
        ),
        (
            ["status", f"--json={KEY}"],
            "phytrace-edge status: error: argument --json: ignored explicit argument *** "
            "(see phytrace-edge status --help)",
        ),
        (  # the key where the command should be
            ["--phycloud-api-key", KEY, "run"],
            "phytrace-edge: error: argument COMMAND: invalid choice: *** (choose from ",
        ),
    ],
    ids=["unrecognized", "unrecognized=", "short-and-loose", "ambiguous", "ignored", "command"],
)
def test_a_mistyped_option_is_one_line_without_its_value(argv: list[str], line: str) -> None:
    result = run_cli(*argv, timeout=60)
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(line), result.stderr
    assert "Zq8v2K9x7" not in result.stderr


@pytest.mark.parametrize(
    ("message", "shown"),
    [
        (
            "unrecognized arguments: --a b --c=d -ef",
            "unrecognized arguments: --a *** --c=*** -e***",
        ),
        ("unrecognized arguments: key with spaces", "unrecognized arguments: *** *** ***"),
        ("unrecognized arguments: --x\nsecret", "unrecognized arguments: --x***"),
        ("unrecognized arguments: - --", "unrecognized arguments: - --"),
        (
            "argument --limit: invalid int value: 'secret'",
            "argument --limit: invalid int value: ***",
        ),
        (
            "the following arguments are required: action",
            "the following arguments are required: action",
        ),
    ],
)
def test_argparse_messages_lose_their_values(message: str, shown: str) -> None:
    assert without_values(message) == shown


ENDPOINT = "https://robot-7:Pw9xSecret@phycloud.example.com/api/v1"


def test_config_masks_the_password_of_a_url() -> None:
    table = run_cli("config", PHYCLOUD_ENDPOINT=ENDPOINT, timeout=60)
    as_json = run_cli("config", "--json", PHYCLOUD_ENDPOINT=ENDPOINT, timeout=60)
    assert table.returncode == 0 and as_json.returncode == 0, table.stderr + as_json.stderr
    (row,) = [line for line in table.stdout.splitlines() if line.startswith("PHYCLOUD_ENDPOINT")]
    assert row.split()[1] == "https://robot-7:***@phycloud.example.com/api/v1"
    value = json.loads(as_json.stdout)["PHYCLOUD_ENDPOINT"]["value"]
    assert value == "https://robot-7:***@phycloud.example.com/api/v1"
    printed = table.stdout + table.stderr + as_json.stdout + as_json.stderr
    assert "Pw9xSecret" not in printed
