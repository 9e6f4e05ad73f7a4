"""The transport bounds every request by HTTP_TIMEOUT_S through httpx's public transport
interface only (issue 34): no private attribute of httpx is set, the deadline backend
holds on the direct and on the proxied path, and httpcore's errors reach the sender as
the httpx classes ``ship/transport.py`` and ``ship/tls.py`` catch.

The stalled peers are listening sockets that never accept: the kernel completes the
TCP handshake and buffers what the client sends, and no answer ever comes, without a
thread or a sleep."""

from __future__ import annotations

import ast
import socket
import ssl
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

import httpcore
import httpx
import pytest

from phytrace_edge.errors import TransientSendError
from phytrace_edge.redact import Secret
from phytrace_edge.ship import bounded_http, tls, transport
from phytrace_edge.ship.bounded_http import BoundedTransport, Deadline
from phytrace_edge.ship.tls import TlsOptions
from phytrace_edge.ship.transport import HttpTransport
from tests.network.proxy import ConnectProxy

HIDDEN = "127.0.0.2"  # only the proxy routes here
PER_OPERATION_S = 30.0  # httpx's own timeouts: far beyond the deadline, so never what fires
DEADLINE_S = 0.3
BOUND_S = 10.0  # a bound, not a speed: without the deadline a request lasts PER_OPERATION_S


@pytest.fixture
def silent_port() -> Iterator[int]:
    """A 127.0.0.1 port that takes connections and never says a word."""
    with socket.create_server(("127.0.0.1", 0), backlog=16) as listener:
        yield listener.getsockname()[1]


def _client(
    ssl_context: ssl.SSLContext | None, deadline: Deadline, proxy: str | None
) -> httpx.Client:
    bounded = BoundedTransport(ssl_context, deadline, proxy)
    return httpx.Client(transport=bounded, timeout=PER_OPERATION_S)


def _timed(work: Callable[[], object]) -> tuple[float, BaseException | None]:
    started = time.monotonic()
    try:
        work()
    except Exception as exc:
        return time.monotonic() - started, exc
    return time.monotonic() - started, None


@pytest.mark.parametrize("module", [transport, bounded_http], ids=lambda m: m.__name__)
def test_the_transport_names_nothing_private_of_httpx_or_httpcore(module: ModuleType) -> None:
    tree = ast.parse(Path(module.__file__).read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            assert not (node.module or "").startswith(("httpx._", "httpcore._")), node.module
        if isinstance(node, ast.Import):
            for alias in node.names:
                assert not alias.name.startswith(("httpx._", "httpcore._")), alias.name
        if isinstance(node, ast.Attribute) and node.attr.startswith("_"):
            dunder = node.attr.startswith("__") and node.attr.endswith("__")
            own = isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")
            # e.g. ``transport._pool = ...``: httpx's internals, which change without notice
            assert dunder or own, f"line {node.lineno}: .{node.attr} of another's object"


@pytest.mark.parametrize("proxy", [None, "http://robot:pw@127.0.0.1:3128"], ids=["direct", "proxy"])
def test_the_client_transport_is_our_public_one_not_a_patched_httpx_transport(
    proxy: str | None,
) -> None:
    bounded = BoundedTransport(None, Deadline(), proxy)
    assert isinstance(bounded, httpx.BaseTransport)
    assert not isinstance(bounded, httpx.HTTPTransport)
    assert "_pool" not in vars(bounded)
    bounded.close()


def test_a_silent_server_is_cut_off_at_the_deadline_on_the_direct_path(silent_port: int) -> None:
    deadline = Deadline()
    with _client(None, deadline, None) as client:
        deadline.until = time.monotonic() + DEADLINE_S
        took, exc = _timed(lambda: client.post(f"http://127.0.0.1:{silent_port}/events"))
    assert isinstance(exc, httpx.ReadTimeout), repr(exc)
    assert took < BOUND_S


def test_a_silent_proxy_is_cut_off_at_the_deadline(silent_port: int) -> None:
    """The connection to the proxy runs on the deadline backend too."""
    deadline = Deadline()
    with _client(None, deadline, f"http://127.0.0.1:{silent_port}") as client:
        deadline.until = time.monotonic() + DEADLINE_S
        took, exc = _timed(lambda: client.post(f"http://{HIDDEN}:80/events"))
    assert isinstance(exc, httpx.ReadTimeout), repr(exc)
    assert took < BOUND_S


@pytest.mark.parametrize("scheme", ["http", "https"], ids=["forwarded", "connect-tunnel"])
def test_a_silent_server_behind_a_proxy_is_cut_off_at_the_deadline(
    silent_port: int, scheme: str
) -> None:
    """http: the proxy forwards and waits; https: the proxy tunnels (CONNECT) and the
    TLS handshake through the tunnel gets no answer."""
    deadline = Deadline()
    context = tls.context(TlsOptions()) if scheme == "https" else None
    with ConnectProxy({f"{HIDDEN}:{silent_port}": ("127.0.0.1", silent_port)}) as proxy:
        with _client(context, deadline, proxy.url) as client:
            deadline.until = time.monotonic() + DEADLINE_S
            url = f"{scheme}://{HIDDEN}:{silent_port}/events"
            took, exc = _timed(lambda: client.post(url))
        assert (proxy.forwarded, proxy.tunnels) == ((1, 0) if scheme == "http" else (0, 1))
    expected = httpx.ReadTimeout if scheme == "http" else httpx.ConnectTimeout
    assert isinstance(exc, expected), repr(exc)
    assert took < BOUND_S


@pytest.mark.parametrize("proxy", [False, True], ids=["direct", "proxy"])
def test_no_connection_is_opened_once_the_deadline_has_passed(
    silent_port: int, proxy: bool
) -> None:
    deadline = Deadline()
    via = f"http://127.0.0.1:{silent_port}" if proxy else None
    with _client(None, deadline, via) as client:
        deadline.until = time.monotonic() - 1
        with pytest.raises(httpx.ConnectTimeout, match="HTTP_TIMEOUT_S passed"):
            client.post(f"http://127.0.0.1:{silent_port}/events")


def test_a_silent_proxy_is_a_timeout_for_the_sender(silent_port: int) -> None:
    sender_side = HttpTransport(
        f"http://{HIDDEN}:80/api/v1",
        Secret(""),
        DEADLINE_S,
        proxy=f"http://127.0.0.1:{silent_port}",
    )
    took, exc = _timed(lambda: sender_side.post_events(b"{}", {}))
    sender_side.close()
    assert isinstance(exc, TransientSendError), repr(exc)
    assert "timeout: no complete answer within HTTP_TIMEOUT_S" in str(exc)
    assert "through proxy" in str(exc)
    assert took < BOUND_S


def test_a_proxy_refusing_its_credentials_is_httpx_s_proxy_error() -> None:
    context = tls.context(TlsOptions())
    with ConnectProxy({}, credentials=("robot", "right")) as proxy:
        client = _client(context, Deadline(), f"http://127.0.0.1:{proxy.port}")
        with client, pytest.raises(httpx.ProxyError, match="407"):
            client.post(f"https://{HIDDEN}:443/events")
        assert proxy.refused == 1


def _failing(failure: Exception) -> Iterator[bytes]:
    yield b"{"
    raise failure


HTTPCORE_ERRORS = [
    "ConnectTimeout",
    "ReadTimeout",
    "WriteTimeout",
    "PoolTimeout",
    "TimeoutException",
    "ConnectError",
    "ReadError",
    "WriteError",
    "NetworkError",
    "ProxyError",
    "UnsupportedProtocol",
    "LocalProtocolError",
    "RemoteProtocolError",
    "ProtocolError",
]


@pytest.mark.parametrize("in_body", [False, True], ids=["sending", "body"])
@pytest.mark.parametrize("name", HTTPCORE_ERRORS)
def test_each_httpcore_error_becomes_httpx_s_of_the_same_name(name: str, in_body: bool) -> None:
    failure = getattr(httpcore, name)("what httpcore said")
    with pytest.raises(httpx.TransportError) as caught:
        if in_body:  # while the answer is read, as a trickle is cut off
            list(bounded_http._Body(_failing(failure)))
        else:
            with bounded_http._as_httpx_errors():
                raise failure
    assert type(caught.value) is getattr(httpx, name)
    assert str(caught.value) == "what httpcore said"
    assert caught.value.__cause__ is failure  # tls.handshake_failure follows the chain


def test_an_error_httpcore_does_not_raise_passes_as_it_is() -> None:
    failure = ValueError("not httpcore's")
    with pytest.raises(ValueError, match="not httpcore's") as caught:
        list(bounded_http._Body(_failing(failure)))
    assert caught.value is failure
