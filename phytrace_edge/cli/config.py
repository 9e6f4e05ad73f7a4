"""``phytrace-edge config``: the effective settings and where each came from."""

from __future__ import annotations

import argparse

from phytrace_edge.cli.common import print_json, shown_value
from phytrace_edge.config import LoadedSettings, setting_infos

LOGS = False

NAME = "config"
HELP = "print the effective settings and their sources"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Print the effective settings and where each came from (the API key as ***)."""
    rows = [
        (
            info.env,
            shown_value(info.key, getattr(loaded.settings, info.key)),
            loaded.origins[info.key],
        )
        for info in setting_infos()
    ]
    if args.json:
        print_json({env: {"value": value, "source": origin} for env, value, origin in rows})
        return 0
    width = max(len(env) for env, _, _ in rows)
    value_width = min(48, max(len(value) for _, value, _ in rows))
    for env, value, origin in rows:
        print(f"{env:<{width}}  {value:<{value_width}}  {origin}")
    return 0
