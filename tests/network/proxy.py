"""A company's HTTP proxy on 127.0.0.1: CONNECT tunnels (https) and forwarded requests
(http), optional Basic authentication, and a log of every request head it saw. Real
sockets, in threads of the test process, closed at the end of the test.

``routes`` maps a target ``host:port`` to the loopback address that serves it: the
bridge asks for a name only the proxy can reach, so a bridge that ignored the proxy
could not deliver at all (and no name is ever looked up in DNS: the targets are IP
addresses of the loopback network that nothing listens on directly)."""

from __future__ import annotations

import base64
import select
import socket
import ssl
import threading
from collections.abc import Mapping
from typing import TypeVar

HEAD_MAX = 65536
Server = TypeVar("Server", bound="LoopbackServer")


class LoopbackServer:
    """Accepts connections on a free 127.0.0.1 port, each served by ``serve`` in a
    thread of its own, until the ``with`` block ends."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._listener = socket.create_server(("127.0.0.1", 0))
        self._listener.settimeout(0.2)
        self.port = self._listener.getsockname()[1]
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()

    def __enter__(self: Server) -> Server:
        self._start(self._accept)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(10)
        self._listener.close()

    def serve(self, client: socket.socket) -> None:
        raise NotImplementedError

    def _start(self, target: object, *args: object) -> None:
        thread = threading.Thread(target=target, args=args, daemon=True)  # type: ignore[arg-type]
        with self._lock:
            self._threads.append(thread)
        thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except TimeoutError:
                continue
            self._start(self.serve, client)


class ConnectProxy(LoopbackServer):
    """``with ConnectProxy(routes) as proxy:`` then ``proxy.url``."""

    def __init__(
        self, routes: Mapping[str, tuple[str, int]], credentials: tuple[str, str] | None = None
    ) -> None:
        super().__init__()
        self.routes = dict(routes)
        self.credentials = credentials
        self.heads: list[bytes] = []  # every request head, as received
        self.tunnels = 0
        self.forwarded = 0
        self.refused = 0

    @property
    def url(self) -> str:
        if self.credentials:
            user, password = self.credentials
            return f"http://{user}:{password}@127.0.0.1:{self.port}"
        return f"http://127.0.0.1:{self.port}"

    def saw(self, text: str) -> bool:
        """Whether ``text`` appeared in any request head the proxy read."""
        with self._lock:
            return any(text.encode() in head for head in self.heads)

    def serve(self, client: socket.socket) -> None:
        client.settimeout(10)
        with client:
            try:
                head, rest = _read_head(client)
            except OSError:
                return
            if head is None:
                return
            with self._lock:
                self.heads.append(head)
            method, target = _request_line(head)
            if not self._authorized(head):
                with self._lock:
                    self.refused += 1
                client.sendall(
                    b"HTTP/1.1 407 Proxy Authentication Required\r\n"
                    b'Proxy-Authenticate: Basic realm="proxy"\r\nContent-Length: 0\r\n\r\n'
                )
                return
            if method == "CONNECT":
                self._tunnel(client, target, rest)
            else:
                self._forward(client, head, rest, target)

    def _authorized(self, head: bytes) -> bool:
        if self.credentials is None:
            return True
        token = base64.b64encode(":".join(self.credentials).encode()).decode()
        return f"proxy-authorization: basic {token}".lower() in head.decode("latin-1").lower()

    def _route(self, target: str) -> tuple[str, int] | None:
        return self.routes.get(target)

    def _tunnel(self, client: socket.socket, target: str, rest: bytes) -> None:
        address = self._route(target)
        if address is None:
            client.sendall(b"HTTP/1.1 502 Bad Gateway\r\nContent-Length: 0\r\n\r\n")
            return
        with self._lock:
            self.tunnels += 1
        with socket.create_connection(address, timeout=10) as upstream:
            client.sendall(b"HTTP/1.1 200 Connection established\r\n\r\n")
            if rest:
                upstream.sendall(rest)
            relay(client, upstream, self._stop)

    def _forward(self, client: socket.socket, head: bytes, rest: bytes, target: str) -> None:
        """An http request in absolute form: sent on to the route of its host:port."""
        host_port = target.split("://", 1)[-1].split("/", 1)[0]
        address = self._route(host_port)
        if address is None:
            client.sendall(b"HTTP/1.1 502 Bad Gateway\r\nContent-Length: 0\r\n\r\n")
            return
        with self._lock:
            self.forwarded += 1
        path = "/" + target.split("://", 1)[-1].split("/", 1)[-1]
        first, _, headers = head.partition(b"\r\n")
        method, _, version = first.decode("latin-1").split(" ", 2)
        kept = [
            line
            for line in headers.split(b"\r\n")
            if line and not line.lower().startswith((b"proxy-", b"connection:"))
        ]
        request = (
            f"{method} {path} {version}\r\n".encode()
            + b"\r\n".join([*kept, b"Connection: close"])
            + b"\r\n\r\n"
            + rest
        )
        with socket.create_connection(address, timeout=10) as upstream:
            upstream.sendall(request)
            relay(client, upstream, self._stop)


def _read_head(connection: socket.socket) -> tuple[bytes | None, bytes]:
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = connection.recv(65536)
        if not chunk or len(data) > HEAD_MAX:
            return None, b""
        data += chunk
    head, _, rest = data.partition(b"\r\n\r\n")
    return head + b"\r\n\r\n", rest


def _request_line(head: bytes) -> tuple[str, str]:
    parts = head.split(b"\r\n", 1)[0].decode("latin-1").split(" ")
    return (parts[0], parts[1]) if len(parts) >= 2 else ("", "")


def relay(a: socket.socket, b: socket.socket, stop: threading.Event) -> None:
    """Copy bytes both ways until either side closes (or the proxy stops)."""
    peers = {a: b, b: a}
    while not stop.is_set():
        # TLS may hold decrypted bytes that select cannot see
        readable = [s for s in peers if isinstance(s, ssl.SSLSocket) and s.pending()]
        if not readable:
            readable, _, _ = select.select(list(peers), [], [], 0.2)
        for source in readable:
            try:
                data = source.recv(65536)
            except OSError:
                return
            if not data:
                return
            try:
                peers[source].sendall(data)
            except OSError:
                return
