"""``phytrace-edge stub``: the PhyCloud dev stub (HTTP API, live page, fault injection)."""

from __future__ import annotations

import argparse

from phytrace_edge.cli.common import checked
from phytrace_edge.config import LoadedSettings
from phytrace_edge.config.parsers import int_between, non_negative_float, path_value
from phytrace_edge.errors import EXIT_OK, ConfigError

FRACTION = non_negative_float(1)
ERROR_STATUS = int_between(400, 599)

TAKES_SETTINGS = False


NAME = "stub"
HELP = "run the PhyCloud dev stub (HTTP server)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--host", type=checked(host, "host"), default="127.0.0.1", help="address to listen on"
    )
    parser.add_argument(
        "--port",
        type=checked(int_between(0, 65535), "port"),
        default=8000,
        help="port (0 = any free port)",
    )
    parser.add_argument(
        "--db",
        type=checked(path_value, "path"),
        default="phycloud-stub.db",
        help="the stub's SQLite file",
    )
    parser.add_argument("--api-key", help="require this Bearer key (default: accept any)")
    parser.add_argument(
        "--error-rate",
        type=checked(FRACTION, "fraction"),
        default=0.0,
        help="fraction answered with errors",
    )
    parser.add_argument(
        "--error-status",
        type=checked(ERROR_STATUS, "status"),
        default=503,
        help="status of those errors",
    )
    parser.add_argument(
        "--fixed-status",
        type=checked(ERROR_STATUS, "status"),
        help="answer every POST with this status",
    )
    parser.add_argument(
        "--retry-after",
        type=checked(header_value, "value"),
        help="Retry-After value sent with injected errors (seconds or an HTTP-date)",
    )
    parser.add_argument(
        "--latency",
        type=checked(non_negative_float(60), "seconds"),
        default=0.0,
        help="seconds before answering",
    )
    parser.add_argument(
        "--drop-rate",
        type=checked(FRACTION, "fraction"),
        default=0.0,
        help="fraction of POSTs whose connection is dropped after storing",
    )
    parser.add_argument(
        "--partial-rejects",
        action="store_true",
        help="answer schema violations with 200 and per-event rejections",
    )
    parser.add_argument(
        "--seed",
        type=checked(int_between(0, 2**32 - 1), "seed"),
        help="seed of the fault injection RNG",
    )
    parser.add_argument(
        "--tls-cert",
        type=checked(path_value, "path"),
        help="serve https with this certificate (PEM)",
    )
    parser.add_argument(
        "--tls-key", type=checked(path_value, "path"), help="the certificate's private key (PEM)"
    )
    parser.add_argument(
        "--tls-client-ca",
        type=checked(path_value, "path"),
        help="require client certificates signed by this CA (PEM): mutual TLS",
    )


def host(raw: str) -> str:
    """An address to bind: a name or an IPv4 or IPv6 address, nothing else."""
    if (
        not raw
        or len(raw) > 253
        or not all(c.isascii() and (c.isalnum() or c in ".-:") for c in raw)
    ):
        raise ValueError("a host name or an IP address, like 127.0.0.1 or ::1")
    return raw


def header_value(raw: str) -> str:
    if not 0 < len(raw) <= 64 or not all(" " <= c <= "~" for c in raw):
        raise ValueError("up to 64 printable ASCII characters")
    return raw


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
    if args.tls_client_ca and not args.tls_cert:
        raise ConfigError("--tls-client-ca needs --tls-cert and --tls-key")
    tls = (args.tls_cert, args.tls_key) if args.tls_cert else None
    try:
        run_stub(
            args.host, args.port, args.db, args.api_key, faults, args.seed, tls, args.tls_client_ca
        )
    except OSError as exc:  # the address is taken, not ours, or the certificate unreadable
        raise ConfigError(f"stub on {args.host}:{args.port}: {exc.strerror or exc}") from None
    return EXIT_OK
