"""Hostile values for every setting (from the environment and from a config file) and
for every argument of every command: each is either accepted, or refused with exactly
one line on stderr and exit code 2 — never a traceback, never a hang."""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path
from unittest import mock

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from phytrace_edge.cli import COMMANDS, command_parser, main
from phytrace_edge.cli.common import shown_value
from phytrace_edge.config import load_settings, setting_infos
from phytrace_edge.config.loading import default_state_dir
from phytrace_edge.errors import ConfigError
from tests.processes import python_env

SETTINGS = setting_infos()
NASTY = [
    "",
    " ",
    "-1",
    "0",
    "nan",
    "inf",
    "-inf",
    "1e309",
    "9" * 400,
    "٣",  # Arabic-Indic three: int() reads it as 3
    "１２",  # fullwidth digits
    "1.9",
    "1_000",
    "0x10",
    "None",
    "true",
    "a\nb",
    "a\rb",
    "\t",
    "/dev/zero",
    "/etc/passwd",
    "http://a..b/",
    "http://127.0.0.1:abc/api",
    "http://127.0.0.1:99999/api",
    "https://",
    "bag:",
    "bag:/etc/passwd",
    "=",
    "/odom=",
    "/odom=/x,/odom",
    "1GiBB",
    "1.5PB",
    "-5MiB",
    "x" * 5000,
    "é",
    "🤖",
]
TEXT = st.one_of(
    st.sampled_from(NASTY),
    st.text(
        alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"),
        max_size=40,
    ),
    st.integers(min_value=-(10**30), max_value=10**30).map(str),
    st.floats().map(str),
)
# What a TOML file can hold, beyond text: numbers, booleans, arrays, tables.
TOML_VALUES = st.one_of(
    TEXT,
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(),
    st.booleans(),
    st.lists(st.one_of(st.integers(), TEXT), max_size=3),
    st.dictionaries(st.sampled_from(["/odom", "/scan", "x"]), TEXT, max_size=2),
)


def run_main(argv: list[str], env: dict[str, str]) -> tuple[int, str]:
    code, _, stderr = run_main_output(argv, env)
    return code, stderr


def run_main_output(argv: list[str], env: dict[str, str]) -> tuple[int, str, str]:
    """``main(argv)`` in this process with only ``env`` of the settings: its exit code,
    stdout and stderr."""
    stdout, stderr = io.StringIO(), io.StringIO()
    clean = {k: v for k, v in os.environ.items() if k.upper() not in _names()}
    with (
        mock.patch.dict(os.environ, {**clean, **env}, clear=True),
        contextlib.redirect_stderr(stderr),
        contextlib.redirect_stdout(stdout),
    ):
        try:
            code = main(argv)
        except SystemExit as exit:  # argparse exits on its own
            code = int(exit.code or 0)
    return code, stdout.getvalue(), stderr.getvalue()


def _names() -> set[str]:
    return {name for info in SETTINGS for name in (info.env, *info.aliases)} | {"PHYTRACE_CONFIG"}


def assert_one_line_refusal(code: int, stderr: str) -> None:
    assert "Traceback" not in stderr
    assert code in (0, 2), (code, stderr)
    if code == 2:
        lines = stderr.strip().splitlines()
        assert len(lines) == 1, stderr
        assert "error:" in lines[0]


DEFAULTS = {info.key: info.default for info in SETTINGS}


def kept(key: str, parsed: object) -> str:
    """How ``config`` shows a parsed value: no queue path is the default place."""
    if key == "queue_path" and parsed is None:
        parsed = str(Path(default_state_dir(os.environ)) / "queue.db")
    return shown_value(key, parsed)


def refused_across_settings(key: str, parsed: object) -> str | None:
    """The refusal of a value its own parser takes: the one rule across settings."""
    values = {**DEFAULTS, key: parsed}
    low, high = values["retry_min_s"], values["retry_max_s"]
    if high < low:
        return f"RETRY_MAX_S={high:g}: must be >= RETRY_MIN_S ({low:g})"
    return None


@pytest.mark.parametrize("info", SETTINGS, ids=lambda info: info.env)
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(value=TEXT)
def test_a_hostile_setting_from_the_environment(info, value: str) -> None:
    """What ``config`` says of a hostile value is what the setting's parser decides:
    kept as parsed, from the environment; or refused in one line with the parser's
    reason. A blank value counts as unset."""
    code, stdout, stderr = run_main_output(["config", "--json"], {info.env: value})
    assert "Traceback" not in stderr
    if not value.strip():
        assert (code, stderr) == (0, "")
        assert json.loads(stdout)[info.env]["source"] == "default"
        return
    try:
        parsed = info.parse(value)
    except ValueError as exc:
        assert (code, stdout) == (2, "")
        [line] = stderr.splitlines()
        assert line.startswith(f"phytrace-edge: error: {info.env}=")
        assert line.endswith(f": must be {exc}")
        if info.key == "phycloud_api_key" and len(value) >= 4:
            assert value not in stderr
        return
    refusal = refused_across_settings(info.key, parsed)
    if refusal is not None:
        assert (code, stdout, stderr) == (2, "", f"phytrace-edge: error: {refusal}\n")
        return
    assert (code, stderr) == (0, ""), stderr
    assert json.loads(stdout)[info.env] == {
        "value": kept(info.key, parsed),
        "source": f"env {info.env}",
    }


@pytest.mark.parametrize("info", SETTINGS, ids=lambda info: info.key)
@settings(max_examples=40, deadline=None)
@given(value=TOML_VALUES)
def test_a_hostile_setting_from_a_config_file(info, value: object) -> None:
    """A hostile value in a config file is kept as its parser reads it, or refused in
    one line that names the file, the setting and the parser's reason."""
    label = "config file x.toml"
    try:
        parsed = info.parse(value)
    except ValueError as exc:
        with pytest.raises(ConfigError) as refused:
            load_settings(config_file={info.key: value}, file_label=label)
        message = str(refused.value)
        assert "\n" not in message
        assert message.startswith(f"{label}: {info.key}=")
        assert message.endswith(f": must be {exc}")
        return
    refusal = refused_across_settings(info.key, parsed)
    if refusal is not None:
        with pytest.raises(ConfigError) as refused:
            load_settings(config_file={info.key: value}, file_label=label)
        assert str(refused.value) == refusal
        return
    loaded = load_settings(config_file={info.key: value}, file_label=label)
    assert loaded.origins[info.key] == label
    assert shown_value(info.key, getattr(loaded.settings, info.key)) == kept(info.key, parsed)


def options_with_values() -> list[tuple[str, str]]:
    found = []
    for name in COMMANDS:
        for action in command_parser(name)._actions:
            if (
                action.option_strings
                and action.nargs != 0
                and not action.dest.startswith("setting_")
            ):
                found.append((name, action.option_strings[-1]))
    return found


@pytest.mark.parametrize(("command", "option"), options_with_values())
@settings(max_examples=30, deadline=None)
@given(value=TEXT)
def test_a_hostile_command_argument(command: str, option: str, value: str) -> None:
    parser = command_parser(command)
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr):
        try:
            parser.parse_args([option, value, *(["list"] if command == "dead-letters" else [])])
            code = 0
        except SystemExit as exit:
            code = int(exit.code or 0)
    assert_one_line_refusal(code, stderr.getvalue())


@settings(max_examples=40, deadline=None)
@given(ids=st.lists(TEXT, min_size=1, max_size=3))
def test_hostile_dead_letter_ids(ids: list[str]) -> None:
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr):
        try:
            command_parser("dead-letters").parse_args(["purge", "--", *ids])
            code = 0
        except SystemExit as exit:
            code = int(exit.code or 0)
    assert_one_line_refusal(code, stderr.getvalue())


@pytest.mark.parametrize(
    "content",
    [b"\xff\xfe invalid utf-8 \x80", b"batch_size = 1.9\n", b"[[x]]\nbad = \n", b"a" * 2_000_000],
    ids=["not-utf8", "float-for-int", "not-toml", "too-big"],
)
def test_a_hostile_config_file(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "config.toml"
    path.write_bytes(content)
    code, stderr = run_main(["config", "--config", str(path)], {})
    assert code == 2
    assert_one_line_refusal(code, stderr)


@pytest.mark.parametrize("path", ["/dev/zero", "/", "/nonexistent/config.toml"])
def test_a_config_path_that_is_no_file_does_not_hang(path: str) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "config"],
        capture_output=True,
        text=True,
        timeout=30,  # /dev/zero used to be read forever
        env=python_env(PHYTRACE_CONFIG=path),
    )
    assert result.returncode == 2
    assert_one_line_refusal(result.returncode, result.stderr)


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("QUEUE_MAX_BYTES", "9" * 400),
        ("BATCH_SIZE", "٣"),
        ("BATCH_SIZE", "1.9"),
        ("CA_BUNDLE", "/etc/passwd"),
        ("PHYCLOUD_ENDPOINT", "http://127.0.0.1:abc/api"),
        ("PHYCLOUD_ENDPOINT", "http://a..b/"),
        ("SAMPLE_RATE_HZ", "nan"),
        ("QUEUE_TTL_S", "1e309"),
        ("TOPIC_REMAP", "/odom=not a topic"),
        ("SOURCE_ID", "robot\n2"),
    ],
)
def test_values_that_were_once_accepted_or_crashed_are_refused(name: str, value: str) -> None:
    code, stderr = run_main(["config"], {name: value})
    assert code == 2, f"{name}={value!r} was accepted"
    assert_one_line_refusal(code, stderr)
    assert stderr.startswith(f"phytrace-edge: error: {name}=")


def test_a_float_from_a_config_file_is_not_cut_to_a_whole_number() -> None:
    with pytest.raises(ConfigError, match=r"batch_size=1\.9: must be a whole number"):
        load_settings(config_file={"batch_size": 1.9}, file_label="config file x.toml")
