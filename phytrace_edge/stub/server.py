"""Run the PhyCloud dev stub: an ASGI app on uvicorn, on a socket we bind ourselves so
port 0 works and the real port is printed (tests read it from the first line)."""

from __future__ import annotations

import logging
import socket
import ssl
import sys
from pathlib import Path

import uvicorn

from phytrace_edge.stub.app import DroppedConnection, Stub, create_app
from phytrace_edge.stub.faults import Faults
from phytrace_edge.stub.store import StubStore


class _HideInjectedDrops(logging.Filter):
    """An injected dropped connection is not a server error worth a traceback."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not (record.exc_info and isinstance(record.exc_info[1], DroppedConnection))


def bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # restart on the same port
    sock.bind((host, port))
    sock.listen(1024)
    return sock


def run_stub(
    host: str,
    port: int,
    db: str | Path,
    api_key: str | None,
    faults: Faults,
    seed: int | None,
    tls: tuple[str, str] | None = None,
    client_ca: str | None = None,
) -> None:
    """Serve until interrupted; with ``client_ca``, only clients presenting a
    certificate that CA signed are served (mutual TLS)."""
    faults.check()
    store = StubStore(db)
    app = create_app(Stub(store, faults, api_key, seed))
    sock = bind(host, port)
    bound_port = sock.getsockname()[1]
    logging.getLogger("uvicorn.error").addFilter(_HideInjectedDrops())
    certfile, keyfile = tls or (None, None)
    server = uvicorn.Server(
        uvicorn.Config(
            app,
            log_level="warning",
            access_log=False,
            lifespan="off",
            ssl_certfile=certfile,
            ssl_keyfile=keyfile,
            ssl_ca_certs=client_ca,
            ssl_cert_reqs=ssl.CERT_REQUIRED if client_ca else ssl.CERT_NONE,
        )
    )
    shown_host = f"[{host}]" if ":" in host else host
    base = f"{'https' if tls else 'http'}://{shown_host}:{bound_port}"
    sys.stdout.write(f"PhyCloud stub listening on {base} (endpoint {base}/api/v1, db {db})\n")
    sys.stdout.flush()
    try:
        server.run(sockets=[sock])
    finally:
        store.close()
