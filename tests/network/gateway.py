"""A TLS gateway in front of the stub, as a company or PhyCloud terminates mutual TLS
(nginx, Envoy): OpenSSL on the server side, requiring a client certificate signed by
the given CA, relaying the plain bytes to the stub on 127.0.0.1. Unlike an asyncio
server, it sends the TLS alert that says why a client was refused."""

from __future__ import annotations

import socket
import ssl
from pathlib import Path

from tests.network.pki import Issued
from tests.network.proxy import LoopbackServer, relay


class MutualTlsGateway(LoopbackServer):
    """``with MutualTlsGateway(server, client_ca, upstream_port) as gateway:``."""

    def __init__(self, server: Issued, client_ca: Path, upstream_port: int) -> None:
        super().__init__()
        self.context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        self.context.load_cert_chain(server.cert, server.key)
        self.context.load_verify_locations(cafile=client_ca)
        self.context.verify_mode = ssl.CERT_REQUIRED
        self.upstream_port = upstream_port
        self.accepted = 0
        self.refused: list[str] = []  # why each refused handshake failed

    @property
    def endpoint(self) -> str:
        return f"https://127.0.0.1:{self.port}/api/v1"

    def serve(self, client: socket.socket) -> None:
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
