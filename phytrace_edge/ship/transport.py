"""One HTTP request for a batch and the client that sends it to PhyCloud: the only
code of the bridge that talks HTTP, with ``bounded_http.py``.

The body is assembled from the events' JSON as stored in the queue, without decoding
and re-encoding them: ``{"events": [<json>, <json>, ...]}``, compressed by a
``BodyEncoder`` (python-zstandard's compressors must not be shared between threads,
so each sender owns one), with an idempotency key over its event ids.

``HttpTransport`` POSTs it and returns a ``Reply``. One long-lived httpx client keeps
the connection alive between batches. Network failures (timeouts, refused or dropped
connections) become ``TransientSendError`` here, at the boundary, so the retry policy
only ever sees project errors.

A hostile or broken server must not hold the sender: HTTP_TIMEOUT_S bounds the *whole*
request, not each read (httpx's timeouts are per operation, so a server that trickles
one byte every few seconds would otherwise hold a request for hours), and at most
``MAX_REPLY_BYTES`` of any answer are read (a multi-GB body must not reach memory).
The deadline is kept by ``bounded_http.py``'s transport, which this client runs on.
"""

from __future__ import annotations

import gzip
import hashlib
import ipaddress
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol
from urllib.parse import urlsplit

import httpx
import zstandard

from phytrace_edge._version import __version__
from phytrace_edge.errors import EndpointRefusedError, TransientSendError
from phytrace_edge.queue.records import Batch, QueuedEvent
from phytrace_edge.redact import Secret, redact, redact_url
from phytrace_edge.ship import tls
from phytrace_edge.ship.api_key import ApiKey
from phytrace_edge.ship.bounded_http import BoundedTransport, Deadline
from phytrace_edge.ship.responses import Reply
from phytrace_edge.ship.tls import TlsOptions

log = logging.getLogger(__name__)

# Measured on backlog batches (tools/bench_outage.py): zstd 1 is both faster and
# smaller than 3 on telemetry; gzip 6 sends 30% fewer bytes than 3 for 2x the CPU,
# which the pipeline hides behind the request in flight
GZIP_LEVEL = 6
ZSTD_LEVEL = 1
USER_AGENT = f"phytrace-edge/{__version__}"


@dataclass(frozen=True)
class Prepared:
    """A claimed batch, encoded and ready to go on the wire, and its lane."""

    batch: Batch
    body: bytes
    headers: dict[str, str]
    lane: str = "backfill"


def events_body(events: Sequence[QueuedEvent]) -> bytes:
    """The JSON body ``{"events": [...]}`` of a batch."""
    return b'{"events":[' + b",".join(event.json for event in events) + b"]}"


class BodyEncoder:
    """Compresses request bodies for ``Content-Encoding: encoding`` (gzip, zstd or
    none); one per thread."""

    def __init__(self, encoding: str) -> None:
        self.encoding = encoding
        self._zstd = zstandard.ZstdCompressor(level=ZSTD_LEVEL) if encoding == "zstd" else None

    def encode(self, body: bytes) -> bytes:
        if self.encoding == "gzip":
            return gzip.compress(body, GZIP_LEVEL, mtime=0)
        if self._zstd is not None:
            return self._zstd.compress(body)
        return body


def idempotency_key(events: Sequence[QueuedEvent]) -> str:
    """The same batch always gets the same key: sha256 over its event ids, in order."""
    digest = hashlib.sha256()
    for event in events:
        digest.update(event.event_id.encode())
        digest.update(b"\n")
    return digest.hexdigest()


def request_headers(events: Sequence[QueuedEvent], encoding: str) -> dict[str, str]:
    """Headers of a batch request, except Authorization (the transport adds that)."""
    headers = {
        "Content-Type": "application/json",
        "Idempotency-Key": idempotency_key(events),
        "User-Agent": USER_AGENT,
    }
    if encoding != "none":
        headers["Content-Encoding"] = encoding
    return headers


# ---------------------------------------------------------------- the client

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


class HttpTransport:
    """httpx client for ``{endpoint}/events`` with the API key as a Bearer token,
    directly or through ``proxy`` (``ship/proxy.py``), trusting and presenting what
    ``tls`` says (``ship/tls.py``)."""

    def __init__(
        self,
        endpoint: str,
        api_key: Secret | ApiKey,
        timeout_s: float,
        ca_bundle: str | None = None,
        *,
        tls_options: TlsOptions | None = None,
        proxy: str | None = None,
    ) -> None:
        self.url = f"{endpoint.rstrip('/')}/events"
        self.host = urlsplit(endpoint).hostname or endpoint
        self.proxy = proxy
        self._timeout_s = timeout_s
        self._key = api_key if isinstance(api_key, ApiKey) else ApiKey(api_key)
        options = self._tls_options = tls_options or TlsOptions(ca_bundle=ca_bundle)
        self._client_cert = options.client is not None
        if self._key.secret and urlsplit(endpoint).scheme == "http" and not is_loopback(endpoint):
            log.warning(
                "PHYCLOUD_ENDPOINT %s is plain http to a non-loopback host: the API key would "
                "cross the network unencrypted - use https",
                redact_url(endpoint),
            )
        # TLS only for https: the CA certificates cost 1.2 MiB an http endpoint never uses
        https = urlsplit(endpoint).scheme == "https"
        self._deadline = Deadline()
        self._client = httpx.Client(
            timeout=httpx.Timeout(timeout_s),
            transport=BoundedTransport(
                tls.context(options) if https else None, self._deadline, proxy
            ),
            follow_redirects=False,
        )

    @property
    def api_key(self) -> ApiKey:
        return self._key

    def figures(self) -> dict[str, Any]:
        """How this transport reaches PhyCloud, for ``status`` (nothing secret)."""
        options = self._tls_options
        trust = "none (http)"
        if self.url.startswith("https:"):
            trust = f"system store {tls.system_store() or '(none found: certifi)'}"
            if options.ca_bundle:
                trust += f" + CA_BUNDLE {options.ca_bundle}"
        client = options.client
        return {
            "endpoint": redact_url(self.url.rsplit("/events", 1)[0]),
            "proxy": None if self.proxy is None else redact_url(self.proxy),
            "trust": trust,
            "client_cert": None if client is None else client.cert,
            "client_cert_expires_at": None if client is None else self._cert_expiry(client.cert),
            "api_key_from": self._key.where,
        }

    @staticmethod
    def _cert_expiry(path: str) -> float | None:
        try:
            return tls.certificate_expiry(path)
        except (OSError, ValueError):  # checked at start; a file replaced since
            return None

    def post_events(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        reply = self._post(body, headers)
        if reply.status in (401, 403) and self._key.reload():
            # a rotated key file: the new key at once, not after RETRY_MAX_S
            log.warning(
                "PhyCloud refused the API key (HTTP %d); %s holds a new one: sending with it",
                reply.status,
                self._key.where,
            )
            reply = self._post(body, headers)
        return reply

    def _post(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        self._deadline.until = time.monotonic() + self._timeout_s
        key = self._key.secret
        sent = {**headers, "Authorization": f"Bearer {key.reveal()}"} if key else dict(headers)
        try:
            with self._client.stream("POST", self.url, content=body, headers=sent) as r:
                answer = _read_at_most(r, MAX_REPLY_BYTES)
                return Reply(
                    r.status_code,
                    self._mask_headers(r.headers),
                    self._mask(answer),
                    # again after decoding: JSON may escape the key (\/, \u002f)
                    mask=lambda text: redact(text, self._key.leak_forms),
                )
        except httpx.TimeoutException as exc:
            raise TransientSendError(
                f"timeout: no complete answer within HTTP_TIMEOUT_S ({type(exc).__name__})"
                + self._via()
            ) from exc
        except httpx.ProxyError as exc:
            raise self._proxy_failure(exc) from exc
        except httpx.TransportError as exc:
            refused = tls.handshake_failure(exc, self.host, self._client_cert)
            if refused is not None:
                raise EndpointRefusedError(f"{refused} [{self._safe(exc)}]") from exc
            raise TransientSendError(
                f"{type(exc).__name__}: {self._safe(exc)}{self._via()}{self._hint(exc)}"
            ) from exc
        finally:
            self._deadline.until = None

    def _proxy_failure(self, exc: httpx.ProxyError) -> TransientSendError:
        """The proxy answered CONNECT with an error: its credentials refused (407) or
        the destination forbidden (403) are for the operator to fix; anything else
        (502: the proxy cannot reach PhyCloud) passes like an outage."""
        text = self._safe(exc)
        proxy = redact_url(self.proxy or "")
        if "407" in text:
            return EndpointRefusedError(
                f"proxy {proxy} refused its credentials ({text}) - check the user and "
                "password in HTTPS_PROXY (or PHYCLOUD_PROXY)"
            )
        if "403" in text:
            return EndpointRefusedError(
                f"proxy {proxy} does not allow {self.host} ({text}) - ask for PhyCloud's "
                "host to be allowed"
            )
        return TransientSendError(f"ProxyError: {text}{self._via()}")

    def _hint(self, exc: httpx.TransportError) -> str:
        """A server that closes an https connection without a word may be refusing a
        missing client certificate (an asyncio server sends no TLS alert to say so)."""
        silent = isinstance(exc, httpx.RemoteProtocolError) and "without sending" in str(exc)
        if silent and self.url.startswith("https:") and not self._client_cert:
            return (
                " - if PhyCloud (or a gateway before it) requires a client certificate, "
                "set CLIENT_CERT and CLIENT_KEY"
            )
        return ""

    def _via(self) -> str:
        return "" if self.proxy is None else f" (through proxy {redact_url(self.proxy)})"

    def _mask(self, body: bytes) -> bytes:
        """An answer as it may be kept (a dead letter keeps PhyCloud's words): a server
        that echoes the request's headers must not put the key into the queue."""
        for form in self._key.leak_forms:
            body = body.replace(form.encode("utf-8", "replace"), b"***")
        return body

    def _mask_headers(self, headers: httpx.Headers) -> dict[str, str]:
        return {name: redact(value, self._key.leak_forms) for name, value in headers.items()}

    def _safe(self, exc: BaseException) -> str:
        """An exception's text as it may go into logs and status: the key never."""
        text = redact(str(exc), self._key.leak_forms)
        if self.proxy is not None:  # the proxy's password, in an error that quotes its URL
            text = text.replace(self.proxy, redact_url(self.proxy))
        return text[:300]

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


class FunctionTransport:
    """A transport made from a function: the fake the sender's tests use."""

    def __init__(self, respond: Callable[[bytes, Mapping[str, str]], Reply]) -> None:
        self._respond = respond

    def post_events(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        return self._respond(body, headers)

    def close(self) -> None:
        """Nothing to release."""
