"""``phytrace-edge run``: the bridge, until SIGTERM or SIGINT (or the end of a bag)."""

from __future__ import annotations

import argparse
import os
import time

from phytrace_edge.errors import EXIT_OK, EXIT_UNHEALTHY, StageFailedError
from phytrace_edge.runtime import wiring

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing
if TYPE_CHECKING:
    from phytrace_edge.config import LoadedSettings

WATCHDOG_IDLE_S = 5.0
POLL_S = 0.2
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
    import logging
    import signal
    import threading

    from phytrace_edge.runtime.sd_notify import SystemdNotifier

    log = logging.getLogger("phytrace_edge")
    stop = threading.Event()
    first_signal_at: list[float] = []

    def on_signal(signum: int, frame: object) -> None:
        if first_signal_at:
            if time.monotonic() - first_signal_at[0] < DUPLICATE_SIGNAL_S:
                return  # the same request twice (Ctrl-C under ros2 launch)
            os._exit(128 + signum)  # the queue is crash-safe: nothing committed is lost
        first_signal_at.append(time.monotonic())
        log.info("received %s: stopping (again to exit at once)", signal.Signals(signum).name)
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    notifier = SystemdNotifier(os.environ)
    service = wiring.build_service(loaded.settings, os.environ, args.ros_args)
    log.info("%s", service.summary())
    service.start()
    notifier.ready(service.status_line())
    # feed the watchdog only while every stage of the service makes progress
    interval = notifier.watchdog_s / 2 if notifier.watchdog_s else WATCHDOG_IDLE_S
    next_check = time.monotonic() + interval
    while not stop.wait(POLL_S):
        if service.finished.is_set() or service.supervisor.failed.is_set():
            break
        if time.monotonic() < next_check:
            continue
        next_check = time.monotonic() + interval
        if service.healthy():
            notifier.watchdog(service.status_line())
        else:
            log.error("a stage of the service makes no progress; letting the watchdog act")
    notifier.stopping()
    service.shutdown(loaded.settings.shutdown_grace_s)
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
        return EXIT_OK if finished.ok else EXIT_UNHEALTHY
    return EXIT_OK
