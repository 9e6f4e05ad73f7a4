"""``phytrace-edge run``: the bridge, until SIGTERM or SIGINT (or the end of a bag)."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import threading
import time
from collections.abc import Callable

from phytrace_edge.cli.signals import on_signals
from phytrace_edge.config import LoadedSettings
from phytrace_edge.errors import EXIT_OK, EXIT_UNHEALTHY, QueueError, StageFailedError
from phytrace_edge.runtime.sd_notify import SystemdNotifier

DUPLICATE_SIGNAL_S = 1.0  # a second signal sooner is the first one delivered twice


NAME = "run"
HELP = "run the bridge (ingest, queue, ship) until stopped"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--rate",
        dest="setting_replay_rate",
        metavar="VALUE",
        help="bag replay speed, same as --replay-rate",
    )


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Run the bridge until SIGTERM or SIGINT; a second signal exits at once, unless it
    follows the first within DUPLICATE_SIGNAL_S: a Ctrl-C in the terminal of ``ros2
    launch`` reaches the bridge itself and again as launch forwards it."""
    from phytrace_edge.runtime import watchdog, wiring  # the whole bridge: only for `run`

    log = logging.getLogger("phytrace_edge")
    stop = threading.Event()
    first_signal_at: list[float] = []

    def on_signal(signum: int) -> None:
        if first_signal_at:
            if time.monotonic() - first_signal_at[0] < DUPLICATE_SIGNAL_S:
                return  # the same request twice (Ctrl-C under ros2 launch)
            os._exit(128 + signum)  # the queue is crash-safe: nothing committed is lost
        first_signal_at.append(time.monotonic())
        log.info("received %s: stopping (again to exit at once)", signal.Signals(signum).name)
        stop.set()

    on_hangup: list[Callable[[], None]] = []  # the service's, once it is built

    def hangup() -> None:
        if on_hangup:
            on_hangup[0]()
        else:
            log.warning("SIGHUP during start-up: ignored")

    on_signals(on_signal, hangup)
    service = wiring.build_service(loaded.settings, os.environ, args.ros_args)
    on_hangup.append(lambda: wiring.read_api_key_again(service))
    watchdog.serve(service, SystemdNotifier(os.environ), stop)
    if service.supervisor.failed.is_set():
        raise StageFailedError(f"{service.supervisor.failure} - exiting so it is restarted")
    finished = service.finished_input()
    if finished is not None:  # a replayed bag
        print(finished.text)
        if service.store_depth_at_stop:
            print(
                f"{service.store_depth_at_stop} event(s) are still queued: "
                "phytrace-edge drain sends them now"
            )
        return EXIT_OK if finished.ok and not service.lost_at_stop else EXIT_UNHEALTHY
    if service.lost_at_stop:
        raise QueueError(
            f"{service.lost_at_stop} event(s) could not be written to the queue "
            f"{loaded.settings.queue_path} before the stop (counted as dropped: "
            "unwritable) - check the disk"
        )
    return EXIT_OK
