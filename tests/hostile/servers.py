"""Misbehaving HTTP servers on 127.0.0.1, for the hostile tests: real sockets, real
bytes, each answering every request the same bad way. They run in a thread of the test
process and are closed at the end of the test."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

Behaviour = Callable[[socket.socket, "BadServer"], None]


@dataclass(frozen=True)
class Request:
    """One request as it arrived: header names in lower case, the body as sent."""

    headers: dict[str, str]
    body: bytes


class BadServer:
    """Accepts connections on a free loopback port; ``behaviour`` answers each one."""

    def __init__(self, behaviour: Behaviour) -> None:
        self.behaviour = behaviour
        self.requests = 0
        self.bytes_sent = 0
        self.stop = threading.Event()
        self._listener = socket.socket()
        self._listener.bind(("127.0.0.1", 0))
        self._listener.listen(16)
        self._listener.settimeout(0.2)
        self.port = self._listener.getsockname()[1]
        self._threads: list[threading.Thread] = []
        self._serving = threading.local()  # each connection is served by a thread of its own
        self._acceptor = threading.Thread(target=self._accept, daemon=True)

    @property
    def endpoint(self) -> str:
        return f"http://127.0.0.1:{self.port}/api/v1"

    def __enter__(self) -> BadServer:
        self._acceptor.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self._acceptor.join(5)
        for thread in self._threads:
            thread.join(5)
        self._listener.close()

    def _accept(self) -> None:
        while not self.stop.is_set():
            try:
                connection, _ = self._listener.accept()
            except TimeoutError:
                continue
            thread = threading.Thread(target=self._serve, args=(connection,), daemon=True)
            self._threads.append(thread)
            thread.start()

    def _serve(self, connection: socket.socket) -> None:
        connection.settimeout(5)
        with connection:
            try:
                while not self.stop.is_set():
                    request = read_request(connection)
                    if request is None:
                        return
                    self._serving.request = request
                    self.requests += 1
                    self.behaviour(connection, self)
            except OSError:
                return  # the client gave up: what these tests want to see

    @property
    def request(self) -> Request:
        """The request the behaviour is answering (in its connection's thread)."""
        return self._serving.request

    def send(self, connection: socket.socket, data: bytes) -> None:
        connection.sendall(data)
        self.bytes_sent += len(data)


def read_request(connection: socket.socket) -> Request | None:
    """Read one HTTP request (headers and a Content-Length body); None at EOF."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = connection.recv(65536)
        if not chunk:
            return None
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    headers = {}
    for line in head.split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        headers[name.strip().lower().decode("latin-1")] = value.strip().decode("latin-1")
    length = int(headers.get("content-length", 0))
    while len(body) < length:
        chunk = connection.recv(65536)
        if not chunk:
            return None
        body += chunk
    return Request(headers, body)


def trickle(interval_s: float) -> Behaviour:
    """A status line and headers one byte every ``interval_s``: never a whole answer."""

    def behave(connection: socket.socket, server: BadServer) -> None:
        for byte in b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nX-Slow: " + b"y" * 10**6:
            if server.stop.wait(interval_s):
                return
            server.send(connection, bytes([byte]))

    return behave


def huge_body(total_bytes: int) -> Behaviour:
    """A 200 announcing ``total_bytes`` of body and sending them as fast as it can."""

    def behave(connection: socket.socket, server: BadServer) -> None:
        server.send(
            connection,
            b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n"
            + f"Content-Length: {total_bytes}\r\n\r\n".encode(),
        )
        chunk = b" " * 65536
        while server.bytes_sent < total_bytes and not server.stop.is_set():
            server.send(connection, chunk)

    return behave


def answer(status: str, headers: dict[str, str], body: bytes) -> Behaviour:
    """The same complete answer to every request (keep-alive)."""
    lines = [f"HTTP/1.1 {status}", f"Content-Length: {len(body)}"]
    lines += [f"{name}: {value}" for name, value in headers.items()]
    raw = ("\r\n".join(lines) + "\r\n\r\n").encode() + body

    def behave(connection: socket.socket, server: BadServer) -> None:
        server.send(connection, raw)

    return behave


def elapsed(work: Callable[[], object]) -> tuple[float, object]:
    started = time.monotonic()
    try:
        result: object = work()
    except Exception as exc:
        result = exc
    return time.monotonic() - started, result
