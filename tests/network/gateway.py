"""A TLS gateway in front of the stub, as a company or PhyCloud terminates mutual TLS
(nginx, Envoy): OpenSSL on the server side, requiring a client certificate signed by
the given CA, relaying the plain bytes to the stub on 127.0.0.1. Unlike an asyncio
server, it sends the TLS alert that says why a client was refused."""

from __future__ import annotations

import socket
import ssl
import threading
from pathlib import Path

from tests.network.pki import Issued
from tests.network.proxy import relay


class MutualTlsGateway:
    """``with MutualTlsGateway(server, client_ca, upstream_port) as gateway:``."""

    def __init__(self, server: Issued, client_ca: Path, upstream_port: int) -> None:
        self.context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        self.context.load_cert_chain(server.cert, server.key)
        self.context.load_verify_locations(cafile=client_ca)
        self.context.verify_mode = ssl.CERT_REQUIRED
        self.upstream_port = upstream_port
        self.accepted = 0
        self.refused: list[str] = []  # why each refused handshake failed
        self._stop = threading.Event()
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.2)
        self.port = self._listener.getsockname()[1]
        self._threads: list[threading.Thread] = []

    @property
    def endpoint(self) -> str:
        return f"https://127.0.0.1:{self.port}/api/v1"

    def __enter__(self) -> MutualTlsGateway:
        self._spawn(self._accept)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(10)
        self._listener.close()

    def _spawn(self, target: object, *args: object) -> None:
        thread = threading.Thread(target=target, args=args, daemon=True)  # type: ignore[arg-type]
        self._threads.append(thread)
        thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            self._spawn(self._serve, client)

    def _serve(self, client: socket.socket) -> None:
        client.settimeout(10)
        try:
            secured = self.context.wrap_socket(client, server_side=True)
        except (ssl.SSLError, OSError) as exc:
            self.refused.append(str(exc))
            client.close()
            return
        self.accepted += 1
        with secured, socket.create_connection(("127.0.0.1", self.upstream_port), 10) as up:
            relay(secured, up, self._stop)
