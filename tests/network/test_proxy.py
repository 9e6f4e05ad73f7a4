"""Behind a company proxy: HTTPS_PROXY/HTTP_PROXY/NO_PROXY honoured as curl honours
them, CONNECT for https so the proxy never sees the key, proxy credentials from the URL
and masked wherever the URL is shown. PhyCloud is reachable only through the proxy:
the endpoint is an address of the loopback network nothing listens on, which only the
proxy routes to the stub."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from phytrace_edge.errors import EndpointRefusedError, TransientSendError
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret
from phytrace_edge.ship.proxy import bypassed, proxy_for
from phytrace_edge.ship.tls import TlsOptions
from phytrace_edge.ship.transport import HttpTransport
from tests.network.delivery import (
    delivered_everything,
    running_status,
    start_bridge,
)
from tests.network.pki import CertificateAuthority
from tests.network.proxy import ConnectProxy
from tests.processes import StubProcess, run_cli, status_json, wait_for
from tests.queue_events import put_events
from tests.udm_events import every_type

KEY = "phk_live_proxy_test_key_0123456789"
HIDDEN = "127.0.0.2"  # only the proxy routes here
BODY, HEADERS = b'{"events": []}', {"Content-Type": "application/json"}


@pytest.fixture
def company_ca(tmp_path: Path) -> CertificateAuthority:
    return CertificateAuthority(tmp_path / "pki")


@pytest.fixture
def https_stub(stub_factory, company_ca: CertificateAuthority) -> StubProcess:
    """The stub on 127.0.0.1, its certificate for the hidden address."""
    server = company_ca.server("phycloud", hosts=(HIDDEN, "127.0.0.1"))
    return stub_factory("--tls-cert", str(server.cert), "--tls-key", str(server.key))


def hidden_endpoint(stub: StubProcess) -> str:
    return f"{stub.scheme}://{HIDDEN}:{stub.port}/api/v1"


def routes(stub: StubProcess) -> dict[str, tuple[str, int]]:
    return {f"{HIDDEN}:{stub.port}": ("127.0.0.1", stub.port)}


def test_the_hidden_endpoint_cannot_be_reached_without_the_proxy(
    https_stub: StubProcess, company_ca: CertificateAuthority
) -> None:
    transport = HttpTransport(
        hidden_endpoint(https_stub), Secret(KEY), 5, tls_options=TlsOptions(str(company_ca.pem))
    )
    with pytest.raises(TransientSendError, match="ConnectError"):
        transport.post_events(BODY, HEADERS)
    transport.close()


def test_a_bridge_behind_a_connect_proxy_delivers_every_event_and_never_shows_it_the_key(
    tmp_path: Path, https_stub: StubProcess, company_ca: CertificateAuthority
) -> None:
    with ConnectProxy(routes(https_stub), credentials=("robot", "s3cret-proxy-pw")) as proxy:
        bridge, settings = start_bridge(
            tmp_path,
            hidden_endpoint(https_stub),
            HTTPS_PROXY=proxy.url,
            CA_BUNDLE=str(company_ca.pem),
            PHYCLOUD_API_KEY=KEY,
        )
        try:
            _, document = wait_for(
                lambda: running_status(settings), 60, "the bridge's first heartbeat"
            )
            assert document["link"]["proxy"] == f"http://robot:***@127.0.0.1:{proxy.port}"
            delivered_everything(bridge, settings, https_stub)
        finally:
            bridge.stop()
        assert proxy.tunnels >= 1
        assert proxy.forwarded == 0 and proxy.refused == 0
        # CONNECT: the proxy saw the target and its own credentials, never the request
        assert proxy.saw(f"CONNECT {HIDDEN}:{https_stub.port}")
        assert not proxy.saw(KEY) and not proxy.saw("Bearer")
    log = (tmp_path / "bridge.log").read_text()
    assert "s3cret-proxy-pw" not in log
    assert "s3cret-proxy-pw" not in str(status_json(**settings)[1])


def test_wrong_proxy_credentials_are_named_in_status_and_nothing_is_lost(
    tmp_path: Path, https_stub: StubProcess, company_ca: CertificateAuthority
) -> None:
    with ConnectProxy(routes(https_stub), credentials=("robot", "right")) as proxy:
        wrong = proxy.url.replace(":right@", ":wrong-pw@")
        bridge, settings = start_bridge(
            tmp_path, hidden_endpoint(https_stub), HTTPS_PROXY=wrong, CA_BUNDLE=str(company_ca.pem)
        )
        try:
            code, document = wait_for(
                lambda: _with_problem(settings, "proxy"), 60, "status to name the proxy"
            )
            assert code == 1
            problem = " | ".join(document["problems"])
            assert "407" in problem and f"robot:***@127.0.0.1:{proxy.port}" in problem
            assert "wrong-pw" not in str(document)
            assert proxy.refused >= 1 and proxy.tunnels == 0
        finally:
            bridge.stop()


def test_phycloud_unreachable_through_the_proxy_is_named_at_once_as_an_outage(
    tmp_path: Path, https_stub: StubProcess, company_ca: CertificateAuthority
) -> None:
    """The proxy cannot reach PhyCloud (502): status names the cause and the proxy
    within seconds, and stays healthy as for any outage (HEALTH_NO_PROGRESS_S)."""
    with ConnectProxy({}) as proxy:  # it routes nowhere
        bridge, settings = start_bridge(
            tmp_path,
            hidden_endpoint(https_stub),
            HTTPS_PROXY=proxy.url,
            CA_BUNDLE=str(company_ca.pem),
        )
        try:
            code, document = wait_for(
                lambda: _with_warning(settings, "through proxy"), 60, "the cause in status"
            )
            warning = next(w for w in document["warnings"] if "through proxy" in w)
            assert "502" in warning and f"127.0.0.1:{proxy.port}" in warning
            assert code == 0 and document["problems"] == []
            assert document["queue"]["depth"] > 0
        finally:
            bridge.stop()


def test_drain_goes_through_the_proxy(
    tmp_path: Path, https_stub: StubProcess, company_ca: CertificateAuthority
) -> None:
    queue = tmp_path / "queue.db"
    with QueueStore.open(queue) as store:
        put_events(
            store, every_type(25, {"source_id": "amr-17", "source_type": "amr"}, time.time())
        )
    with ConnectProxy(routes(https_stub)) as proxy:
        done = run_cli(
            "drain",
            QUEUE_PATH=str(queue),
            PHYCLOUD_ENDPOINT=hidden_endpoint(https_stub),
            HTTPS_PROXY=proxy.url,
            CA_BUNDLE=str(company_ca.pem),
        )
        assert done.returncode == 0, done.stderr
        assert proxy.tunnels >= 1
    assert https_stub.stats()["unique"] == 25


def test_no_proxy_sends_loopback_direct(stub_factory) -> None:
    stub = stub_factory()
    with ConnectProxy({}) as proxy:
        endpoint = stub.endpoint
        chosen = proxy_for(endpoint, {"HTTP_PROXY": proxy.url, "NO_PROXY": "localhost,127.0.0.1"})
        assert chosen is None
        transport = HttpTransport(endpoint, Secret(KEY), 5, proxy=chosen)
        assert transport.post_events(BODY, HEADERS).status == 400  # the stub: an empty batch
        transport.close()
        assert proxy.heads == []


def test_an_http_endpoint_goes_through_http_proxy_as_a_forwarded_request(stub_factory) -> None:
    stub = stub_factory()
    hidden = f"http://{HIDDEN}:{stub.port}/api/v1"
    with ConnectProxy(routes(stub)) as proxy:
        chosen = proxy_for(hidden, {"http_proxy": proxy.url, "HTTPS_PROXY": "http://unused:1"})
        assert chosen == proxy.url
        transport = HttpTransport(hidden, Secret(""), 5, proxy=chosen)
        assert transport.post_events(BODY, HEADERS).status == 400
        transport.close()
        assert proxy.forwarded == 1


def test_a_proxy_that_refuses_the_tunnel_is_a_refusal_not_a_blip(stub_factory) -> None:
    stub = stub_factory()
    with ConnectProxy({}, credentials=("robot", "pw")) as proxy:
        transport = HttpTransport(
            f"https://{HIDDEN}:{stub.port}/api/v1",
            Secret(KEY),
            5,
            proxy=f"http://127.0.0.1:{proxy.port}",
        )
        with pytest.raises(EndpointRefusedError, match="407"):
            transport.post_events(BODY, HEADERS)
        transport.close()


@pytest.mark.parametrize(
    ("env", "expected"),
    [
        ({"HTTPS_PROXY": "http://p:1"}, "http://p:1"),
        ({"https_proxy": "http://lower:1", "HTTPS_PROXY": "http://upper:1"}, "http://lower:1"),
        ({"ALL_PROXY": "http://all:1"}, "http://all:1"),
        ({"HTTPS_PROXY": "p:3128"}, "http://p:3128"),
        ({"HTTP_PROXY": "http://p:1"}, None),  # http's proxy is not https's
        ({"HTTPS_PROXY": "http://p:1", "NO_PROXY": "example.com"}, None),
        ({"HTTPS_PROXY": "http://p:1", "no_proxy": ".example.com"}, None),
        ({"HTTPS_PROXY": "http://p:1", "NO_PROXY": "*"}, None),
        ({"HTTPS_PROXY": "http://p:1", "NO_PROXY": "other.com,ample.com"}, "http://p:1"),
        ({}, None),
    ],
)
def test_the_environment_chooses_the_proxy_as_curl_does(
    env: dict[str, str], expected: str | None
) -> None:
    assert proxy_for("https://api.example.com/v1", env) == expected


def test_the_setting_overrides_the_environment() -> None:
    env = {"HTTPS_PROXY": "http://env:1"}
    assert proxy_for("https://api.example.com", env, "http://setting:2") == "http://setting:2"
    assert proxy_for("https://api.example.com", env, "direct") is None


@pytest.mark.parametrize(
    ("host", "no_proxy", "expected"),
    [
        ("api.example.com", "example.com", True),
        ("example.com", ".example.com", True),
        ("badexample.com", "example.com", False),
        ("10.1.2.3", "10.0.0.0/8", True),
        ("10.1.2.3", "10.1.2.4", False),
        ("::1", "::1", True),
        ("host", " , ", False),
    ],
)
def test_no_proxy_matching(host: str, no_proxy: str, expected: bool) -> None:
    assert bypassed(host, no_proxy) is expected


def _with_warning(settings: dict[str, str], word: str) -> tuple[int, dict] | None:
    code, document = status_json(**settings)
    return (code, document) if any(word in w for w in document.get("warnings", [])) else None


def _with_problem(settings: dict[str, str], word: str) -> tuple[int, dict] | None:
    code, document = status_json(**settings)
    return (code, document) if any(word in p for p in document.get("problems", [])) else None
