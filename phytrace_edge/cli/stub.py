"""``phytrace-edge stub``: the PhyCloud dev stub (HTTP API, live page, fault injection)."""

from __future__ import annotations

import argparse

from phytrace_edge.errors import EXIT_OK, ConfigError

TYPE_CHECKING = False  # typing.TYPE_CHECKING without importing typing
if TYPE_CHECKING:
    from phytrace_edge.config import LoadedSettings

TAKES_SETTINGS = False


NAME = "stub"
HELP = "run the PhyCloud dev stub (HTTP server)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default="127.0.0.1", help="address to listen on")
    parser.add_argument("--port", type=int, default=8000, help="port (0 = any free port)")
    parser.add_argument("--db", default="phycloud-stub.db", help="the stub's SQLite file")
    parser.add_argument("--api-key", help="require this Bearer key (default: accept any)")
    parser.add_argument(
        "--error-rate", type=float, default=0.0, help="fraction answered with errors"
    )
    parser.add_argument("--error-status", type=int, default=503, help="status of those errors")
    parser.add_argument("--fixed-status", type=int, help="answer every POST with this status")
    parser.add_argument("--retry-after", help="Retry-After value sent with injected errors")
    parser.add_argument("--latency", type=float, default=0.0, help="seconds before answering")
    parser.add_argument(
        "--drop-rate",
        type=float,
        default=0.0,
        help="fraction of POSTs whose connection is dropped after storing",
    )
    parser.add_argument(
        "--partial-rejects",
        action="store_true",
        help="answer schema violations with 200 and per-event rejections",
    )
    parser.add_argument("--seed", type=int, help="seed of the fault injection RNG")
    parser.add_argument("--tls-cert", help="serve https with this certificate (PEM)")
    parser.add_argument("--tls-key", help="the certificate's private key (PEM)")


def run(args: argparse.Namespace, loaded: LoadedSettings) -> int:
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
        raise ConfigError(str(exc)) from None
    if bool(args.tls_cert) != bool(args.tls_key):
        raise ConfigError("--tls-cert and --tls-key go together")
    tls = (args.tls_cert, args.tls_key) if args.tls_cert else None
    run_stub(args.host, args.port, args.db, args.api_key, faults, args.seed, tls)
    return EXIT_OK
