"""What the commands share: the setting flags, value display, errors, JSON output."""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from typing import Any, NoReturn

from phytrace_edge.config import setting_infos
from phytrace_edge.config.parsers import positive_float
from phytrace_edge.redact import MASK, Secret, redact_url
from phytrace_edge.units import format_bytes

SETTING_PREFIX = "setting_"
HELP_WIDTH = 100


# argparse's messages that quote what was typed: the value in them is masked, since
# a mistyped option (`--phycloud-apikey KEY`) would otherwise put the key in the journal
_QUOTED_VALUES = (
    (re.compile(r"^(ambiguous option: [^=\s]*=).*?( could match )"), rf"\g<1>{MASK}\g<2>"),
    (re.compile(r"(invalid choice: ).*?( \(choose from )"), rf"\g<1>{MASK}\g<2>"),
    (re.compile(r"(ignored explicit argument ).*$"), rf"\g<1>{MASK}"),
    (re.compile(r"(invalid [\w-]+ value: ).*$"), rf"\g<1>{MASK}"),
)
_UNRECOGNIZED = "unrecognized arguments: "
_OPTION_NAME = re.compile(r"--[A-Za-z0-9][-A-Za-z0-9_]*|-[A-Za-z0-9]")


class Parser(argparse.ArgumentParser):
    """argparse, with a mistake reported as one line (argparse prints the usage first,
    which wraps to many lines) that never quotes a value typed, and a help width of our
    own (argparse would import shutil to ask the terminal, which costs every command's
    start)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _formatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        message = without_values(message)
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def without_values(message: str) -> str:
    """An argparse error on one line, with the values typed masked: unrecognized
    arguments by option name only (``--phycloud-apikey ***``), the value of an
    ambiguous ``--opt=VALUE``, an invalid choice or an ignored argument as ``***``. The
    settings' own messages name a bad value on purpose, the key's masked
    (config/settings.py); these come before the settings are read."""
    if message.startswith(_UNRECOGNIZED):
        words = message[len(_UNRECOGNIZED) :].split(" ")
        message = _UNRECOGNIZED + " ".join(_option_only(word) for word in words)
    for pattern, masked in _QUOTED_VALUES:
        message = pattern.sub(masked, message)
    return " ".join(message.splitlines())


def _option_only(word: str) -> str:
    """An unrecognized argument as an error may show it: an option's name, never a value
    (neither the next word nor what follows ``=`` or a short option's letter)."""
    name = _OPTION_NAME.match(word)
    if name is None:
        return word if word in ("", "-", "--") else MASK
    rest = word[name.end() :]
    if not rest:
        return word
    return name.group() + ("=" if rest.startswith("=") else "") + MASK


def _formatter(prog: str) -> argparse.HelpFormatter:
    return argparse.HelpFormatter(prog, width=HELP_WIDTH)


def checked(parse: Callable[[Any], Any], what: str) -> Callable[[str], Any]:
    """An argparse ``type`` from one of the settings' parsers: the same rules, and the
    same one-line message, for a command's own arguments."""

    def convert(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{text[:40]!r} is not {exc}") from None

    convert.__name__ = what  # argparse names the type in some messages
    return convert


# flags that keep another name working: the docs say --input
FLAG_ALIASES = {"bridge_input": ("--input",)}


def add_setting_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("settings (each also an environment variable)")
    group.add_argument("--config", metavar="PATH", help="TOML config file (or PHYTRACE_CONFIG)")
    group.add_argument(
        "--env-file",
        metavar="PATH",
        help="KEY=VALUE settings file, e.g. the service's (or PHYTRACE_ENV_FILE); "
        "the environment wins",
    )
    for info in setting_infos():
        group.add_argument(
            *FLAG_ALIASES.get(info.key, ()),
            info.flag,
            dest=SETTING_PREFIX + info.key,
            metavar="VALUE",
            help=f"{info.doc} [{info.env}]",
        )


def setting_flags(args: argparse.Namespace) -> dict[str, Any]:
    """The settings given as flags, by key (None: not given)."""
    return {
        key[len(SETTING_PREFIX) :]: value
        for key, value in vars(args).items()
        if key.startswith(SETTING_PREFIX)
    }


def shown_value(key: str, value: Any) -> str:
    """A setting's value as ``config`` prints it: the API key redacted, and the password
    in a URL (``https://user:***@proxy:3128``)."""
    if isinstance(value, Secret):
        return str(value) or "(empty)"
    if value is None:
        return "(none)"
    if key.endswith("_bytes") and isinstance(value, int):
        return f"{value} ({format_bytes(value)})"
    if isinstance(value, (dict, frozenset)):
        items = value.items() if isinstance(value, dict) else ((v, None) for v in sorted(value))
        text = ",".join(k if v is None else f"{k}={v}" for k, v in items) or "(none)"
    else:
        text = str(value)
    return redact_url(text) if "://" in text else text


def error(message: str) -> None:
    """One line on stderr."""
    print(f"phytrace-edge: error: {message}", file=sys.stderr)


def print_json(document: Any) -> None:
    """``document`` as indented JSON (stdlib json: ``status`` starts faster without orjson)."""
    sys.stdout.write(json.dumps(document, indent=2, ensure_ascii=False) + "\n")


def add_timeout_flag(parser: argparse.ArgumentParser) -> None:
    """``--timeout S`` of the commands that send (``drain``, ``import``)."""
    parser.add_argument(
        "--timeout",
        type=checked(positive_float(10**7), "seconds"),
        help="give up after this many seconds",
    )
