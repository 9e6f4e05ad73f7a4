"""httpx on httpcore's pool, every request bounded by one deadline (HTTP_TIMEOUT_S).

httpx's timeouts are per operation, so a server that trickles one byte every few
seconds would hold a request for hours. The deadline lives in the network streams
httpcore reads from and writes to: each operation gets the time left, never more.
httpx has no setting for its pool's backend, so ``BoundedTransport`` does the work of
httpx's own transport on this backend, with public APIs only: the request turned into
httpcore's, the answer back into httpx's, httpcore's errors into httpx's same-named
public ones (which ``transport.py`` and ``tls.py`` catch).
"""

from __future__ import annotations

import ssl
import threading
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import httpcore
import httpx

from phytrace_edge.ship import tls
from phytrace_edge.ship.tls import TlsOptions


class Deadline(threading.local):
    """When the request in flight on this thread must be over (monotonic seconds)."""

    until: float | None = None

    def clamp(self, timeout: float | None, expired: type[Exception]) -> float | None:
        """``timeout`` cut to the time left; raises ``expired`` when none is left."""
        if self.until is None:
            return timeout
        left = self.until - time.monotonic()
        if left <= 0:
            raise expired("HTTP_TIMEOUT_S passed before the answer was complete")
        return left if timeout is None else min(timeout, left)


class DeadlineStream(httpcore.NetworkStream):
    def __init__(self, stream: httpcore.NetworkStream, deadline: Deadline) -> None:
        self._stream, self._deadline = stream, deadline

    def read(self, max_bytes: int, timeout: float | None = None) -> bytes:
        return self._stream.read(max_bytes, self._deadline.clamp(timeout, httpcore.ReadTimeout))

    def write(self, buffer: bytes, timeout: float | None = None) -> None:
        self._stream.write(buffer, self._deadline.clamp(timeout, httpcore.WriteTimeout))

    def close(self) -> None:
        self._stream.close()

    def start_tls(
        self,
        ssl_context: ssl.SSLContext,
        server_hostname: str | None = None,
        timeout: float | None = None,
    ) -> httpcore.NetworkStream:
        timeout = self._deadline.clamp(timeout, httpcore.ConnectTimeout)
        return DeadlineStream(
            self._stream.start_tls(ssl_context, server_hostname, timeout), self._deadline
        )

    def get_extra_info(self, info: str) -> Any:
        return self._stream.get_extra_info(info)


class DeadlineBackend(httpcore.NetworkBackend):
    """httpcore's own sync backend, with every operation bounded by the deadline."""

    def __init__(self, deadline: Deadline) -> None:
        self._backend = httpcore.SyncBackend()
        self._deadline = deadline

    def connect_tcp(
        self,
        host: str,
        port: int,
        timeout: float | None = None,
        local_address: str | None = None,
        socket_options: Iterable[Any] | None = None,
    ) -> httpcore.NetworkStream:
        timeout = self._deadline.clamp(timeout, httpcore.ConnectTimeout)
        stream = self._backend.connect_tcp(host, port, timeout, local_address, socket_options)
        return DeadlineStream(stream, self._deadline)

    def sleep(self, seconds: float) -> None:
        self._backend.sleep(seconds)


# httpcore's errors -> httpx's same-named public ones (which _post catches); subclasses first
_HTTPX_ERRORS: tuple[tuple[type[Exception], type[httpx.TransportError]], ...] = (
    (httpcore.ConnectTimeout, httpx.ConnectTimeout),
    (httpcore.ReadTimeout, httpx.ReadTimeout),
    (httpcore.WriteTimeout, httpx.WriteTimeout),
    (httpcore.PoolTimeout, httpx.PoolTimeout),
    (httpcore.TimeoutException, httpx.TimeoutException),
    (httpcore.ConnectError, httpx.ConnectError),
    (httpcore.ReadError, httpx.ReadError),
    (httpcore.WriteError, httpx.WriteError),
    (httpcore.NetworkError, httpx.NetworkError),
    (httpcore.ProxyError, httpx.ProxyError),
    (httpcore.UnsupportedProtocol, httpx.UnsupportedProtocol),
    (httpcore.LocalProtocolError, httpx.LocalProtocolError),
    (httpcore.RemoteProtocolError, httpx.RemoteProtocolError),
    (httpcore.ProtocolError, httpx.ProtocolError),
)


@contextmanager
def _as_httpx_errors() -> Iterator[None]:
    try:
        yield
    except Exception as exc:
        for theirs, ours in _HTTPX_ERRORS:
            if isinstance(exc, theirs):
                raise ours(str(exc)) from exc  # tls.handshake_failure reads the chain
        raise  # not httpcore's: as it is


def _core_url(url: httpx.URL) -> httpcore.URL:
    return httpcore.URL(
        scheme=url.raw_scheme, host=url.raw_host, port=url.port, target=url.raw_path
    )


class _Body(httpx.SyncByteStream):
    """httpcore's answer body, its errors made httpx's (a trickle is cut off here)."""

    def __init__(self, body: Iterable[bytes]) -> None:
        self._body = body

    def __iter__(self) -> Iterator[bytes]:
        with _as_httpx_errors():
            yield from self._body

    def close(self) -> None:
        getattr(self._body, "close", lambda: None)()  # httpcore's has one; typed Iterable


class BoundedTransport(httpx.BaseTransport):
    """httpcore's pool, direct or through ``proxy``, on the deadline backend."""

    def __init__(
        self, ssl_context: ssl.SSLContext | None, deadline: Deadline, proxy: str | None
    ) -> None:
        limits = httpx.Limits()  # httpx's defaults; nothing is read from the environment
        options: dict[str, Any] = {
            "ssl_context": ssl_context,  # None: an http endpoint, which never needs one
            "max_connections": limits.max_connections,
            "max_keepalive_connections": limits.max_keepalive_connections,
            "keepalive_expiry": limits.keepalive_expiry,
            "network_backend": DeadlineBackend(deadline),
        }
        if proxy is None:
            self._connections = httpcore.ConnectionPool(**options)
            return
        parsed = httpx.Proxy(proxy)  # CONNECT for https: the proxy relays bytes it cannot read
        self._connections = httpcore.HTTPProxy(
            proxy_url=_core_url(parsed.url),  # httpx.Proxy took the credentials out of it
            proxy_auth=parsed.raw_auth,
            proxy_headers=parsed.headers.raw,
            proxy_ssl_context=tls.context(TlsOptions()) if parsed.url.scheme == "https" else None,
            **options,
        )

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        url, headers, body = _core_url(request.url), request.headers.raw, request.stream
        sent = httpcore.Request(  # the client's timeouts ride in the extensions
            request.method, url, headers=headers, content=body, extensions=request.extensions
        )
        with _as_httpx_errors():
            answer = self._connections.handle_request(sent)
        assert isinstance(answer.stream, Iterable)  # a sync pool's body
        stream, ext = _Body(answer.stream), answer.extensions
        return httpx.Response(answer.status, headers=answer.headers, stream=stream, extensions=ext)

    def close(self) -> None:
        self._connections.close()
