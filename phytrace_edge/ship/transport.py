"""The only module that talks HTTP: POST a batch body to PhyCloud, get a ``Reply``.

One long-lived httpx client keeps the connection alive between batches. Network
failures (timeouts, refused or dropped connections) become ``TransientSendError``
here, at the boundary, so the retry policy only ever sees project errors.
"""

from __future__ import annotations

import ipaddress
import logging
import ssl
from collections.abc import Callable, Mapping
from typing import Protocol
from urllib.parse import urlsplit

import httpx

from phytrace_edge.errors import EndpointRefusedError, TransientSendError
from phytrace_edge.redact import Secret
from phytrace_edge.ship.responses import Reply

log = logging.getLogger(__name__)


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
    """httpx client for ``{endpoint}/events`` with the API key as a Bearer token."""

    def __init__(
        self, endpoint: str, api_key: Secret, timeout_s: float, ca_bundle: str | None = None
    ) -> None:
        self.url = f"{endpoint.rstrip('/')}/events"
        if api_key and urlsplit(endpoint).scheme == "http" and not is_loopback(endpoint):
            log.warning(
                "PHYCLOUD_ENDPOINT %s is plain http to a non-loopback host: the API key would "
                "cross the network unencrypted - use https",
                endpoint,
            )
        verify: ssl.SSLContext | bool = True
        if ca_bundle:
            verify = ssl.create_default_context()
            verify.load_verify_locations(cafile=ca_bundle)  # in addition to the system CAs
        headers = {"Authorization": f"Bearer {api_key.reveal()}"} if api_key else {}
        self._client = httpx.Client(
            headers=headers,
            timeout=httpx.Timeout(timeout_s),
            verify=verify,
            follow_redirects=False,
        )

    def post_events(self, body: bytes, headers: Mapping[str, str]) -> Reply:
        try:
            response = self._client.post(self.url, content=body, headers=dict(headers))
        except httpx.TimeoutException as exc:
            raise TransientSendError(f"timeout ({type(exc).__name__})") from exc
        except httpx.TransportError as exc:
            if _untrusted_certificate(exc):
                raise EndpointRefusedError(
                    f"TLS: the certificate of {urlsplit(self.url).hostname} is not trusted "
                    f"({exc}) - set CA_BUNDLE to the CA that signed it"
                ) from exc
            raise TransientSendError(f"{type(exc).__name__}: {exc}") from exc
        return Reply(response.status_code, dict(response.headers), response.content)

    def close(self) -> None:
        self._client.close()


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
