"""The ``phytrace-edge`` command: thin subcommands over the library.

Each command parses its arguments, loads settings, calls one function and turns
project errors into one line on stderr and a non-zero exit (2 for bad input), never a
traceback.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import orjson

from phytrace_edge import __version__
from phytrace_edge.config import (
    LoadedSettings,
    Secret,
    format_bytes,
    ros_parameters,
    setting_infos,
    settings_from_environment,
)
from phytrace_edge.errors import PhytraceError

EXIT_BAD_INPUT = 2
WATCHDOG_IDLE_S = 5.0
log = logging.getLogger("phytrace_edge")
Command = Callable[[argparse.Namespace, LoadedSettings], int]


def _setting_flags(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("settings (each also an environment variable)")
    group.add_argument("--config", metavar="PATH", help="TOML config file (or PHYTRACE_CONFIG)")
    for info in setting_infos():
        group.add_argument(
            info.flag, dest=f"setting_{info.key}", metavar="VALUE", help=f"{info.doc} [{info.env}]"
        )


def _flags(args: argparse.Namespace) -> dict[str, Any]:
    prefix = "setting_"
    return {k[len(prefix) :]: v for k, v in vars(args).items() if k.startswith(prefix)}


def shown_value(key: str, value: Any) -> str:
    """A setting's value as ``config`` prints it (the API key redacted)."""
    if isinstance(value, Secret):
        return str(value) or "(empty)"
    if value is None:
        return "(none)"
    if key.endswith("_bytes") and isinstance(value, int):
        return f"{value} ({format_bytes(value)})"
    if isinstance(value, (dict, frozenset)):
        items = value.items() if isinstance(value, dict) else ((v, None) for v in sorted(value))
        return ",".join(k if v is None else f"{k}={v}" for k, v in items) or "(none)"
    return str(value)


def cmd_config(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Print the effective settings and where each came from."""
    rows = [
        (
            info.env,
            shown_value(info.key, getattr(loaded.settings, info.key)),
            loaded.origins[info.key],
        )
        for info in setting_infos()
    ]
    if args.json:
        document = {env: {"value": value, "source": origin} for env, value, origin in rows}
        sys.stdout.write(orjson.dumps(document, option=orjson.OPT_INDENT_2).decode() + "\n")
        return 0
    width = max(len(env) for env, _, _ in rows)
    value_width = min(48, max(len(value) for _, value, _ in rows))
    for env, value, origin in rows:
        print(f"{env:<{width}}  {value:<{value_width}}  {origin}")
    return 0


def cmd_sim(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Run the simulated delivery robot through the bridge and print the stats."""
    from phytrace_edge.sim.runner import run_simulation

    if args.record:
        from phytrace_edge.sim.recorder import record_simulation

        counts = record_simulation(args.record, args.ticks / 10, args.storage, args.seed)
        print(f"recorded {sum(counts.values())} messages to {args.record} ({args.storage})")
        return 0
    stats = run_simulation(
        args.ticks, settings=loaded.settings, seed=args.seed, realtime=args.realtime
    )
    sys.stdout.write(orjson.dumps(stats, option=orjson.OPT_INDENT_2).decode() + "\n")
    return 0 if stats["events_failed"] == 0 else 1


def _when(unix_s: float) -> str:
    from phytrace_edge.udm.event import format_timestamp

    return format_timestamp(unix_s)


def cmd_dead_letters(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Inspect, export, requeue or purge events PhyCloud rejected for good."""
    from phytrace_edge.queue.dead_letters import DeadLetterBox
    from phytrace_edge.runtime.service import open_queue

    with open_queue(loaded.settings) as store:
        box = DeadLetterBox(store)
        ids = args.ids or None
        if args.action == "list":
            letters = box.list(limit=args.limit)
            print(f"{box.count()} dead letter(s) in {store.path}")
            for letter in letters:
                print(
                    f"{letter.id:>6}  {_when(letter.dead_at)}  {letter.event_id}  "
                    f"{letter.reason}  {(letter.response or '')[:60]}"
                )
        elif args.action == "export":
            if args.output == "-":
                written = box.export(sys.stdout.buffer)
            else:
                with open(args.output, "wb") as out:  # noqa: PTH123 - a binary stream
                    written = box.export(out)
            print(f"exported {written} dead letter(s)", file=sys.stderr)
        elif args.action == "requeue":
            print(f"requeued {box.requeue(ids)} dead letter(s) at the end of the queue")
        else:
            before = (
                None
                if args.older_than_days is None
                else (store.now() - args.older_than_days * 86400)
            )
            if ids is None and before is None and not args.all:
                print(
                    "phytrace-edge: error: purge needs ids, --older-than-days or --all",
                    file=sys.stderr,
                )
                return EXIT_BAD_INPUT
            print(f"purged {box.purge(ids, before=before)} dead letter(s)")
    return 0


def cmd_stub(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Run the PhyCloud dev stub until interrupted."""
    from phytrace_edge.stub.faults import Faults
    from phytrace_edge.stub.server import run_stub

    faults = Faults(
        error_rate=args.error_rate,
        error_status=args.error_status,
        fixed_status=args.fixed_status,
        retry_after=args.retry_after,
        latency_s=args.latency,
        drop_rate=args.drop_rate,
        partial_rejects=args.partial_rejects,
    )
    try:
        faults.check()
    except ValueError as exc:
        print(f"phytrace-edge: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if bool(args.tls_cert) != bool(args.tls_key):
        print("phytrace-edge: error: --tls-cert and --tls-key go together", file=sys.stderr)
        return EXIT_BAD_INPUT
    tls = (args.tls_cert, args.tls_key) if args.tls_cert else None
    run_stub(args.host, args.port, args.db, args.api_key, faults, args.seed, tls)
    return 0


def cmd_run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Run the bridge until SIGTERM or SIGINT; a second signal exits at once."""
    from phytrace_edge.runtime.sd_notify import SystemdNotifier
    from phytrace_edge.runtime.service import BridgeService

    stop = threading.Event()

    def on_signal(signum: int, frame: object) -> None:
        if stop.is_set():
            os._exit(128 + signum)  # the queue is crash-safe: nothing committed is lost
        log.info("received %s: stopping (again to exit at once)", signal.Signals(signum).name)
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    notifier = SystemdNotifier()
    service = BridgeService(loaded.settings, ros_args=args.ros_args)
    log.info("%s", service.summary())
    service.start()
    notifier.ready(service.status_line())
    # feed the watchdog only while every thread of the service is alive
    interval = notifier.watchdog_s / 2 if notifier.watchdog_s else WATCHDOG_IDLE_S
    while not stop.wait(interval) and not service.source.finished.is_set():
        if service.alive():
            notifier.watchdog(service.status_line())
        else:
            log.error("a thread of the service died; letting the watchdog restart it")
    notifier.stopping()
    service.shutdown(loaded.settings.shutdown_grace_s)
    summary = getattr(service.source, "summary", None)
    if summary is not None:  # a replayed bag
        print(summary.describe())
        left = service.store_depth_at_stop
        if left:
            print(f"{left} event(s) are still queued: phytrace-edge drain sends them now")
        return 1 if summary.error else 0
    return 0


def cmd_status(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Show the queue and the service; exit 0 healthy, 1 unhealthy, 3 not running."""
    from phytrace_edge.runtime.health import Thresholds, exit_code, report
    from phytrace_edge.runtime.state import read_snapshot

    s = loaded.settings
    snapshot = read_snapshot(Path(str(s.queue_path)))
    if snapshot is None:
        print(
            f"phytrace-edge: no queue at {s.queue_path}: the bridge never ran with this QUEUE_PATH",
            file=sys.stderr,
        )
        return 3
    limits = Thresholds(
        s.health_stale_s, s.health_no_progress_s, s.queue_warn_fraction, s.queue_max_bytes
    )
    document = report(snapshot, limits, time.time(), str(s.queue_path))
    if args.json:
        sys.stdout.write(orjson.dumps(document, option=orjson.OPT_INDENT_2).decode() + "\n")
    elif not args.quiet:
        print(render_status(document))
    return exit_code(document)


def render_status(d: dict[str, Any]) -> str:
    """The status document as a table for people."""
    state = "HEALTHY" if d["healthy"] else ("UNHEALTHY" if d["problems"] else "NOT RUNNING")
    service, queue = d["service"], d["queue"]
    lines = [f"phytrace-edge status: {state}"]
    if d["heartbeat_age_s"] is None:
        lines.append("  service      never ran with this queue")
    else:
        verb = "running" if d["running"] else "not running"
        lines.append(
            f"  service      {verb} (pid {service.get('pid')}, {service.get('version')}, input "
            f"{service.get('input')}, {service.get('source_id')} -> "
            f"{service.get('endpoint_host')}), heartbeat {d['heartbeat_age_s']:.1f} s ago"
        )
    oldest = "" if queue["oldest_age_s"] is None else f", oldest {queue['oldest_age_s']:.1f} s"
    lines.append(
        f"  queue        {queue['depth']} event(s), {format_bytes(queue['bytes'])} of "
        f"{format_bytes(queue['cap_bytes'])} ({queue['fill']:.0%}){oldest}  {queue['path']}"
    )
    lines.append(
        f"  sent         {d['sent_total']} in total, {d['send_rate_eps']:.1f} events/s, last "
        f"success {d['last_success_at'] or 'never'}"
    )
    if d["last_error"]:
        lines.append(f"  last error   {d['last_error']} at {d['last_error_at']}")
    drops = ", ".join(f"{reason} {n}" for reason, n in d["drops"].items()) or "none"
    lines.append(f"  drops        {drops}")
    lines.append(
        f"  dead letters {d['dead_letters']}"
        + ("  (phytrace-edge dead-letters list)" if d["dead_letters"] else "")
    )
    for topic, t in d["topics"].items():
        age = t.get("last_seen_age_s")
        seen = "" if age is None else f", last {age:.1f} s ago"
        rejected = sum(t.get("rejected", {}).values())
        lines.append(
            f"  {topic:<16} {t['rate_hz']:.1f} Hz, {t['received']} received{seen}"
            + (f", {rejected} rejected" if rejected else "")
        )
    lines += [f"  problem: {problem}" for problem in d["problems"]]
    return "\n".join(lines)


def cmd_drain(args: argparse.Namespace, loaded: LoadedSettings) -> int:
    """Send the whole backlog now; exit 0 only when the queue is empty at the end."""
    from tqdm import tqdm

    from phytrace_edge.runtime.service import http_transport, open_queue, send_policy
    from phytrace_edge.ship import Sender

    settings = loaded.settings
    started = time.monotonic()
    with open_queue(settings) as store:
        sender = Sender(store, http_transport(settings), send_policy(settings))
        signal.signal(signal.SIGINT, lambda signum, frame: sender.stop.set())
        signal.signal(signal.SIGTERM, lambda signum, frame: sender.stop.set())
        depth = store.stats_counter("depth")
        with tqdm(total=depth, unit="ev", desc="draining", file=sys.stderr, disable=None) as bar:

            def progress(sent: int) -> None:
                bar.update(sent)
                bar.set_postfix(left=format_bytes(store.stats_counter("stored_bytes")))

            deadline = None if args.timeout is None else started + args.timeout
            empty = sender.drain(deadline=deadline, progress=progress)
        left = store.stats_counter("depth")
        sender.transport.close()
    elapsed = time.monotonic() - started
    if empty:
        print(f"drained {sender.stats.events_sent} event(s) in {elapsed:.1f} s; the queue is empty")
        return 0
    why = sender.stats.last_error or ("timeout" if args.timeout else "stopped")
    print(f"sent {sender.stats.events_sent} event(s) in {elapsed:.1f} s; {left} left ({why})")
    return 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="phytrace-edge",
        description="PhyTrace edge bridge: ROS 2 topics -> UDM events -> queue -> PhyCloud.",
    )
    parser.add_argument("--version", action="version", version=f"phytrace-edge {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = commands.add_parser("run", help="run the bridge (ingest, queue, ship) until stopped")
    run.add_argument(
        "--rate",
        dest="setting_replay_rate",
        metavar="VALUE",
        help="bag replay speed, same as --replay-rate",
    )
    run.set_defaults(handler=cmd_run)

    status = commands.add_parser(
        "status", help="show the queue and the service; exit 0 healthy, 1 unhealthy, 3 not running"
    )
    status.add_argument("--json", action="store_true", help="print JSON (a stable interface)")
    status.add_argument("--quiet", "-q", action="store_true", help="print nothing: exit code only")
    status.set_defaults(handler=cmd_status)

    drain = commands.add_parser("drain", help="send the whole backlog now, with a progress bar")
    drain.add_argument("--timeout", type=float, help="give up after this many seconds")
    drain.set_defaults(handler=cmd_drain)

    config = commands.add_parser("config", help="print the effective settings and their sources")
    config.add_argument("--json", action="store_true", help="print JSON instead of a table")
    config.set_defaults(handler=cmd_config)

    sim = commands.add_parser("sim", help="run the simulated delivery robot through the bridge")
    sim.add_argument("--ticks", type=int, default=100, help="robot cycles at 10 Hz (default 100)")
    sim.add_argument("--seed", type=int, default=0, help="random seed of the simulated world")
    sim.add_argument("--realtime", action="store_true", help="run at wall-clock pace")
    sim.add_argument(
        "--record",
        metavar="PATH",
        help="record the robot's topics to a rosbag2 at PATH instead (needs [bag])",
    )
    sim.add_argument(
        "--storage", choices=["mcap", "sqlite3"], default="mcap", help="storage of the recorded bag"
    )
    sim.set_defaults(handler=cmd_sim)

    dead = commands.add_parser(
        "dead-letters", help="list, export, requeue or purge events PhyCloud rejected"
    )
    dead.add_argument("action", choices=["list", "export", "requeue", "purge"])
    dead.add_argument("ids", nargs="*", type=int, help="dead letter ids (default: all)")
    dead.add_argument("--limit", type=int, default=100, help="list at most this many")
    dead.add_argument("--output", "-o", default="-", help="export to this file (- = stdout)")
    dead.add_argument("--older-than-days", type=float, help="purge only those older")
    dead.add_argument("--all", action="store_true", help="purge all")
    dead.set_defaults(handler=cmd_dead_letters)

    stub = commands.add_parser("stub", help="run the PhyCloud dev stub (HTTP server)")
    stub.add_argument("--host", default="127.0.0.1", help="address to listen on")
    stub.add_argument("--port", type=int, default=8000, help="port (0 = any free port)")
    stub.add_argument("--db", default="phycloud-stub.db", help="the stub's SQLite file")
    stub.add_argument("--api-key", help="require this Bearer key (default: accept any)")
    stub.add_argument("--error-rate", type=float, default=0.0, help="fraction answered with errors")
    stub.add_argument("--error-status", type=int, default=503, help="status of those errors")
    stub.add_argument("--fixed-status", type=int, help="answer every POST with this status")
    stub.add_argument("--retry-after", help="Retry-After value sent with injected errors")
    stub.add_argument("--latency", type=float, default=0.0, help="seconds before answering")
    stub.add_argument(
        "--drop-rate",
        type=float,
        default=0.0,
        help="fraction of POSTs whose connection is dropped after storing",
    )
    stub.add_argument(
        "--partial-rejects",
        action="store_true",
        help="answer schema violations with 200 and per-event rejections",
    )
    stub.add_argument("--seed", type=int, help="seed of the fault injection RNG")
    stub.add_argument("--tls-cert", help="serve https with this certificate (PEM)")
    stub.add_argument("--tls-key", help="the certificate's private key (PEM)")
    stub.set_defaults(handler=cmd_stub)

    for command in (run, status, drain, config, sim, dead):
        _setting_flags(command)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``phytrace-edge`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    # everything from --ros-args on is for ROS: parameters here, the rest for rclpy
    split = argv.index("--ros-args") if "--ros-args" in argv else len(argv)
    args = build_parser().parse_args(argv[:split])
    args.ros_args = argv[split:]
    ros_args = args.ros_args[1:]
    try:
        loaded = settings_from_environment(
            _flags(args),
            config_path=getattr(args, "config", None),
            ros_params=ros_parameters(ros_args),
        )
        from phytrace_edge.runtime.logs import configure_logging

        settings = loaded.settings
        configure_logging(
            settings.log_level, settings.log_format, [settings.phycloud_api_key.reveal()]
        )
        handler: Command = args.handler
        return handler(args, loaded)
    except PhytraceError as exc:
        print(f"phytrace-edge: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # the reader went away (`| head`): stop quietly, and keep the interpreter's
        # final flush from raising again at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
