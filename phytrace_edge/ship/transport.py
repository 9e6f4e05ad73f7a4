"""The only module that talks HTTP: POST a batch body to PhyCloud, get a ``Reply``.

One long-lived httpx client keeps the connection alive between batches. Network
failures (timeouts, refused or dropped connections) become ``TransientSendError``
here, at the boundary, so the retry policy only ever sees project errors.

A hostile or broken server must not hold the sender: HTTP_TIMEOUT_S bounds the *whole*
request, not each read (httpx's timeouts are per operation, so a server that trickles
one byte every few seconds would otherwise hold a request for hours), and at most
``MAX_REPLY_BYTES`` of any answer are read (a multi-GB body must not reach memory).
The deadline lives in the network streams httpcore reads from and writes to: each
operation gets the time left, never more.
"""

from __future__ import annotations

import ipaddress
import logging
import ssl
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Protocol
from urllib.parse import urlsplit

import httpcore
import httpx

from phytrace_edge.errors import ConfigError, EndpointRefusedError, TransientSendError
from phytrace_edge.redact import Secret, leak_forms, redact
from phytrace_edge.ship.responses import Reply

log = logging.getLogger(__name__)

MAX_REPLY_BYTES = 64 * 1024  # PhyCloud's answer is a small JSON document


class Transport(Protocol):
    """Sends one request body; the sender and its tests depend only on this."""

    def post_events(self, body: bytes, headers: Mapping[str, str]) -> Reply: ...

    def close(self) -> None: ...


def is_loopback(url: str) -> bool:
    host = urlsplit(url).hostname or ""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


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


def _bounded_transport(verify: ssl.SSLContext | bool, deadline: Deadline) -> httpx.HTTPTransport:
    """httpx's transport whose connection pool runs on the deadline backend (httpx has
    no setting for the backend, so its pool is made again with the same defaults)."""
    transport = httpx.HTTPTransport(verify=verify, trust_env=False)
    limits = httpx.Limits()
    transport._pool = httpcore.ConnectionPool(
        ssl_context=transport._pool._ssl_context,
        max_connections=limits.max_connections,
        max_keepalive_connections=limits.max_keepalive_connections,
        keepalive_expiry=limits.keepalive_expiry,
        network_backend=DeadlineBackend(deadline),
    )
    return transport


class HttpTransport:
    """httpx client for ``{endpoint}/events`` with the API key as a Bearer token."""

    def __init__(
        self, endpoint: str, api_key: Secret, timeout_s: float, ca_bundle: str | None = None
    ) -> None:
        self.url = f"{endpoint.rstrip('/')}/events"
        self._timeout_s = timeout_s
        self._key_forms = leak_forms(api_key.reveal())
        if api_key and urlsplit(endpoint).scheme == "http" and not is_loopback(endpoint):
            log.warning(
                "PHYCLOUD_ENDPOINT %s is plain http to a non-loopback host: the API key would "
                "cross the network unencrypted - use https",
                endpoint,
            )
        # TLS only for https: the CA certificates cost 1.2 MiB an http endpoint never uses
        verify: ssl.SSLContext | bool = urlsplit(endpoint).scheme == "https"
        if ca_bundle and verify:
            verify = ssl.create_default_context()
            try:  # in addition to the system CAs
                verify.load_verify_locations(cafile=ca_bundle)
            except (OSError, ssl.SSLError) as exc:
                raise ConfigError(
                    f"CA_BUNDLE={ca_bundle!r}: not a usable CA file ({exc})"
                ) from None
        headers = {"Authorization": f"Bearer {api_key.reveal()}"} if api_key else {}
        self._deadline = Deadline()
        self._client = httpx.Client(
            headers=headers,
            timeout=httpx.Timeout(timeout_s),
            transport=_bounded_transport(verify, self._deadline),
            follow_redirects=False,
        )

    def post_events(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        self._deadline.until = time.monotonic() + self._timeout_s
        try:
            with self._client.stream("POST", self.url, content=body, headers=dict(headers)) as r:
                answer = _read_at_most(r, MAX_REPLY_BYTES)
                return Reply(r.status_code, self._mask_headers(r.headers), self._mask(answer))
        except httpx.TimeoutException as exc:
            raise TransientSendError(
                f"timeout: no complete answer within HTTP_TIMEOUT_S ({type(exc).__name__})"
            ) from exc
        except httpx.TransportError as exc:
            if _untrusted_certificate(exc):
                raise EndpointRefusedError(
                    f"TLS: the certificate of {urlsplit(self.url).hostname} is not trusted "
                    f"({self._safe(exc)}) - set CA_BUNDLE to the CA that signed it"
                ) from exc
            raise TransientSendError(f"{type(exc).__name__}: {self._safe(exc)}") from exc
        finally:
            self._deadline.until = None

    def _mask(self, body: bytes) -> bytes:
        """An answer as it may be kept (a dead letter keeps PhyCloud's words): a server
        that echoes the request's headers must not put the key into the queue."""
        for form in self._key_forms:
            body = body.replace(form.encode("utf-8", "replace"), b"***")
        return body

    def _mask_headers(self, headers: httpx.Headers) -> dict[str, str]:
        return {name: redact(value, self._key_forms) for name, value in headers.items()}

    def _safe(self, exc: BaseException) -> str:
        """An exception's text as it may go into logs and status: the key never."""
        return redact(str(exc), self._key_forms)[:300]

    def close(self) -> None:
        self._client.close()


def _read_at_most(response: httpx.Response, limit: int) -> bytes:
    """The first ``limit`` bytes of the body (decoded), and no more from the network."""
    chunks, size = [], 0
    for chunk in response.iter_bytes():
        chunks.append(chunk)
        size += len(chunk)
        if size >= limit:
            break
    return b"".join(chunks)[:limit]


def _untrusted_certificate(exc: BaseException) -> bool:
    """Whether a connection failed because the server's certificate did not verify: a
    configuration problem to report loudly, not a network blip."""
    cause: BaseException | None = exc
    while cause is not None:
        if isinstance(cause, ssl.SSLCertVerificationError):
            return True
        cause = cause.__cause__ or cause.__context__
    return False


class FunctionTransport:
    """A transport made from a function: the fake the sender's tests use."""

    def __init__(self, respond: Callable[[bytes, Mapping[str, str]], Reply]) -> None:
        self._respond = respond

    def post_events(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        return self._respond(body, headers)

    def close(self) -> None:
        """Nothing to release."""
