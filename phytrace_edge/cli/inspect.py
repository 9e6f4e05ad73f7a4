"""``phytrace-edge inspect FILE...``: what a hand-carry file holds and whether it is
whole, without uploading it (on the robot before the stick leaves, or on a laptop)."""

from __future__ import annotations

import argparse
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from phytrace_edge.cli.common import error, print_json
from phytrace_edge.config import LoadedSettings
from phytrace_edge.errors import EXIT_BAD_INPUT, EXIT_OK, EXIT_UNHEALTHY

if TYPE_CHECKING:  # the report loads the file formats' libraries: run() imports it
    from phytrace_edge.handcarry.report import FileReport

NAME = "inspect"
HELP = (
    "check hand-carry files made by export without uploading them: the manifest, events "
    "per type, the captured time range, every CRC and the checksum; exit 0 when every "
    "file is whole, 1 when one is damaged, 2 when one is not a phytrace-edge export"
)
TAKES_SETTINGS = False
LOGS = False


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("files", nargs="+", metavar="FILE", help="files to check")
    parser.add_argument("--json", action="store_true", help="one JSON document per file")


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    from phytrace_edge.handcarry.format import NotAnExport
    from phytrace_edge.handcarry.report import inspect_file

    worst = EXIT_OK
    for name in args.files:
        path = Path(name)
        if not path.is_file():
            error(f"{path}: no such file")
            worst = max(worst, EXIT_BAD_INPUT)
            continue
        try:
            report = inspect_file(path)
        except NotAnExport as exc:
            error(f"{exc}")
            worst = max(worst, EXIT_BAD_INPUT)
            continue
        if args.json:
            print_json({**asdict(report), "whole": report.whole})
        else:
            print(_describe(report))
        if not report.whole:
            worst = max(worst, EXIT_UNHEALTHY)
    return worst


def _describe(report: FileReport) -> str:
    header, manifest = report.header, report.manifest
    per_type = ", ".join(f"{name} {count}" for name, count in report.per_type.items())
    lines = [
        f"{report.path}: phytrace-edge hand-carry file ({report.format}), written by "
        f"phytrace-edge {header.get('bridge_version', '?')} at {header.get('created_at', '?')}",
        f"  robot        {header.get('source_id', '?')}",
        f"  events       {report.events}" + (f" ({per_type})" if per_type else ""),
        f"  captured     {report.first_captured_at or '-'} to {report.last_captured_at or '-'}",
        f"  schema       UDM {header.get('schema_version', '?')}",
    ]
    if manifest is not None:
        lines.append(f"  queue ids    {manifest.first_id}-{manifest.last_id}")
        lines.append(f"  sha256       {manifest.sha256}")
    lines.append(f"  checks       {', '.join(f'{check} ok' for check in report.checks) or '-'}")
    if report.whole:
        lines.append(f"whole: an import delivers all {report.events} event(s)")
    else:
        lines.append(f"  damaged      {report.damage}")
        lines.append(f"damaged: an import delivers the {report.events} event(s) before the damage")
    return "\n".join(lines)
