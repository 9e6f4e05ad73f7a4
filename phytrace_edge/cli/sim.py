"""``phytrace-edge sim``: the simulated robot through ingest and build, or into a bag."""

from __future__ import annotations

import argparse

from phytrace_edge.cli.common import checked, print_json
from phytrace_edge.config import LoadedSettings
from phytrace_edge.config.parsers import int_between, path_value
from phytrace_edge.errors import EXIT_OK, EXIT_UNHEALTHY

NAME = "sim"
HELP = "run the simulated delivery robot through the bridge"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--ticks",
        type=checked(int_between(0, 10**7), "ticks"),
        default=100,
        help="robot cycles at 10 Hz (default 100)",
    )
    parser.add_argument(
        "--seed",
        type=checked(int_between(0, 2**32 - 1), "seed"),
        default=0,
        help="random seed of the simulated world",
    )
    parser.add_argument("--realtime", action="store_true", help="run at wall-clock pace")
    parser.add_argument(
        "--record",
        metavar="PATH",
        type=checked(path_value, "path"),
        help="record the robot's topics to a rosbag2 at PATH instead (needs [bag])",
    )
    parser.add_argument(
        "--storage", choices=["mcap", "sqlite3"], default="mcap", help="storage of the recorded bag"
    )


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Run the simulated delivery robot through the bridge and print the stats."""
    if args.record:
        from phytrace_edge.sim.recorder import record_simulation

        counts = record_simulation(args.record, args.ticks / 10, args.storage, args.seed)
        print(f"recorded {sum(counts.values())} messages to {args.record} ({args.storage})")
        return EXIT_OK
    from phytrace_edge.runtime.simulation import run_simulation

    stats = run_simulation(
        args.ticks, settings=loaded.settings, seed=args.seed, realtime=args.realtime
    )
    print_json(stats)
    return EXIT_OK if stats["events_failed"] == 0 else EXIT_UNHEALTHY
