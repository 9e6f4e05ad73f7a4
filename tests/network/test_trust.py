"""Whom the bridge trusts, and what it says when a handshake fails: the system's
trust store by default (so a company CA installed with update-ca-certificates is
trusted), SSL_CERT_FILE/SSL_CERT_DIR as OpenSSL honours them, CA_BUNDLE added to the
store, and mutual TLS with CLIENT_CERT/CLIENT_KEY. Real TLS servers (the stub) on
127.0.0.1, a private CA made for each test."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from phytrace_edge.errors import ConfigError, EndpointRefusedError, TransientSendError
from phytrace_edge.redact import Secret
from phytrace_edge.ship import tls
from phytrace_edge.ship.tls import ClientCertificate, TlsOptions
from phytrace_edge.ship.transport import HttpTransport
from tests.network.delivery import (
    delivered_everything,
    running_status,
    start_bridge,
    unhealthy_naming,
)
from tests.network.gateway import MutualTlsGateway
from tests.network.pki import CertificateAuthority
from tests.processes import StubProcess, python_env, run_cli, wait_for

BODY, HEADERS = b'{"events": []}', {"Content-Type": "application/json"}
KEY = "phk_live_tls_test_key_0123456789"


@pytest.fixture
def ca(tmp_path: Path) -> CertificateAuthority:
    return CertificateAuthority(tmp_path / "pki")


def tls_stub(stub_factory, ca: CertificateAuthority, name: str = "phycloud", **kw) -> StubProcess:
    server = ca.server(name, **kw)
    return stub_factory("--tls-cert", str(server.cert), "--tls-key", str(server.key), name=name)


def post(endpoint: str, options: TlsOptions) -> int:
    transport = HttpTransport(endpoint, Secret(KEY), 10, tls_options=options)
    try:
        return transport.post_events(BODY, HEADERS).status
    finally:
        transport.close()


def store_with(tmp_path: Path, *pems: Path) -> Path:
    """A trust store file: the machine's CAs and ``pems``, as update-ca-certificates
    would write /etc/ssl/certs/ca-certificates.crt."""
    system = tls.system_store()
    parts = [Path(system).read_bytes()] if system and Path(system).is_file() else []
    store = tmp_path / "ca-certificates.crt"
    store.write_bytes(b"\n".join([*parts, *(p.read_bytes() for p in pems)]))
    return store


# --------------------------------------------------------------------- trust


def test_a_private_ca_is_not_trusted_by_default_and_the_reason_is_named(
    stub_factory, ca: CertificateAuthority, monkeypatch: pytest.MonkeyPatch
) -> None:
    stub = tls_stub(stub_factory, ca)
    monkeypatch.delenv("SSL_CERT_FILE", raising=False)
    monkeypatch.delenv("SSL_CERT_DIR", raising=False)
    with pytest.raises(EndpointRefusedError) as refused:
        post(stub.endpoint, TlsOptions())
    assert "signed by a CA this robot does not trust" in str(refused.value)
    assert "update-ca-certificates" in str(refused.value)


def test_ssl_cert_file_moves_the_system_store_as_for_curl(
    tmp_path: Path, stub_factory, ca: CertificateAuthority
) -> None:
    stub = tls_stub(stub_factory, ca)
    store = store_with(tmp_path, ca.pem)
    code = (
        "import sys; from phytrace_edge.redact import Secret;"
        "from phytrace_edge.ship.transport import HttpTransport;"
        "t = HttpTransport(sys.argv[1], Secret('k'), 10);"
        "print(t.post_events(b'{\"events\": []}', {'Content-Type': 'application/json'}).status)"
    )
    for env in ({"SSL_CERT_FILE": str(store)}, {"SSL_CERT_DIR": str(_hashed_dir(tmp_path, ca))}):
        clean = {k: v for k, v in python_env().items() if not k.startswith("SSL_CERT_")}
        done = subprocess.run(
            [sys.executable, "-c", code, stub.endpoint],
            capture_output=True,
            text=True,
            timeout=60,
            env={**clean, **env},
        )
        assert done.stdout.strip() == "400", (env, done.stderr[-500:])  # reached: empty batch


def test_ca_bundle_adds_to_the_system_store(
    tmp_path: Path, stub_factory, ca: CertificateAuthority
) -> None:
    """With CA_BUNDLE set, a public CA of the store is still trusted: a second private CA
    stands in for it here, installed in the store the way update-ca-certificates does."""
    in_store = CertificateAuthority(tmp_path / "store-ca", "Store CA")
    stub_by_store = tls_stub(stub_factory, in_store, "by-store")
    stub_by_bundle = tls_stub(stub_factory, ca, "by-bundle")
    store = store_with(tmp_path, in_store.pem)
    os.environ["SSL_CERT_FILE"], before = str(store), os.environ.get("SSL_CERT_FILE")
    try:
        options = TlsOptions(ca_bundle=str(ca.pem))
        assert post(stub_by_store.endpoint, options) == 400
        assert post(stub_by_bundle.endpoint, options) == 400
    finally:
        if before is None:
            os.environ.pop("SSL_CERT_FILE")
        else:
            os.environ["SSL_CERT_FILE"] = before


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("unshare"), reason="needs root")
def test_a_ca_installed_in_the_system_store_is_trusted_by_the_bridge_process(
    tmp_path: Path, stub_factory, ca: CertificateAuthority
) -> None:
    """The bridge, as systemd starts it (no SSL_CERT_* in its environment), in a mount
    namespace where the system's store holds the company CA as update-ca-certificates
    leaves it: it delivers every event."""
    stub = tls_stub(stub_factory, ca)
    bundle = Path("/etc/ssl/certs/ca-certificates.crt")
    if not bundle.is_file():
        pytest.skip("no /etc/ssl/certs/ca-certificates.crt here")
    store = store_with(tmp_path, ca.pem)
    wrapper = tmp_path / "in-namespace.sh"
    wrapper.write_text(
        "#!/bin/sh\nset -e\n"
        f"mount --bind {store} {bundle}\n"
        "unset SSL_CERT_FILE SSL_CERT_DIR\n"  # as systemd starts it: OpenSSL's defaults
        f'exec {sys.executable} -m phytrace_edge "$@"\n'
    )
    wrapper.chmod(0o755)
    command = ["unshare", "--mount", "--propagation", "private", str(wrapper), "run"]
    bridge, settings = start_bridge(tmp_path, stub.endpoint, command, PHYCLOUD_API_KEY=KEY)
    try:
        delivered_everything(bridge, settings, stub)
    finally:
        bridge.stop()


@pytest.mark.parametrize(
    ("kind", "words"),
    [
        ("wrong-name", "is not for 127.0.0.1"),
        ("expired", "has expired"),
    ],
)
def test_a_bad_server_certificate_gets_its_real_reason(
    stub_factory, ca: CertificateAuthority, kind: str, words: str
) -> None:
    if kind == "wrong-name":
        stub = tls_stub(stub_factory, ca, hosts=("phycloud.example.com",))
    else:
        stub = tls_stub(stub_factory, ca, expired=True)
    with pytest.raises(EndpointRefusedError) as refused:
        post(stub.endpoint, TlsOptions(ca_bundle=str(ca.pem)))
    assert words in str(refused.value)
    assert "set CA_BUNDLE" not in str(refused.value)


def test_a_tls_failure_makes_status_unhealthy_at_once_and_keeps_the_events(
    tmp_path: Path, stub_factory, ca: CertificateAuthority
) -> None:
    stub = tls_stub(stub_factory, ca)
    bridge, settings = start_bridge(tmp_path, stub.endpoint, PHYCLOUD_API_KEY=KEY)
    try:
        code, document = wait_for(
            lambda: unhealthy_naming(settings, "does not trust"), 30, "status naming TLS"
        )
        assert code == 1
        assert document["queue"]["depth"] > 0  # kept, not dropped
        assert document["accounting"]["dropped"] == {}
        assert stub.stats()["received"] == 0
    finally:
        bridge.stop()


# --------------------------------------------------------------------- mutual TLS


@pytest.fixture
def gateway(stub_factory, ca: CertificateAuthority) -> Iterator[MutualTlsGateway]:
    """The stub behind a gateway that requires client certificates signed by ``ca``."""
    stub = stub_factory()
    with MutualTlsGateway(ca.server("gateway"), ca.pem, stub.port) as front:
        front.stub = stub  # type: ignore[attr-defined]
        yield front


def test_mutual_tls_delivers_every_event_with_the_robots_certificate(
    tmp_path: Path, gateway: MutualTlsGateway, ca: CertificateAuthority
) -> None:
    robot = ca.client("robot-001")
    bridge, settings = start_bridge(
        tmp_path,
        gateway.endpoint,
        PHYCLOUD_API_KEY=KEY,
        CA_BUNDLE=str(ca.pem),
        CLIENT_CERT=str(robot.cert),
        CLIENT_KEY=str(robot.key),
    )
    try:
        _, document = wait_for(lambda: running_status(settings), 60, "a heartbeat")
        link = document["link"]
        assert link["client_cert"] == str(robot.cert)
        assert 9 * 86400 < link["client_cert_expires_in_s"] <= 10 * 86400
        # ten days left: within the 14 days status warns before
        days = [
            float(found.group(1))
            for w in document["warnings"]
            if (found := re.search(rf"CLIENT_CERT {robot.cert} expires in (\d+\.\d) days", w))
        ]
        assert len(days) == 1 and 9.8 <= days[0] <= 10.0, document["warnings"]
        delivered_everything(bridge, settings, gateway.stub)  # type: ignore[attr-defined]
    finally:
        bridge.stop()
    assert gateway.accepted >= 1 and gateway.refused == []


def test_an_encrypted_client_key_opens_with_its_passphrase_file(
    tmp_path: Path, gateway: MutualTlsGateway, ca: CertificateAuthority
) -> None:
    robot = ca.client("robot-enc", passphrase=b"correct horse")
    secret = tmp_path / "passphrase"
    secret.write_text("correct horse\n")
    client = ClientCertificate(str(robot.cert), str(robot.key), str(secret))
    assert post(gateway.endpoint, TlsOptions(str(ca.pem), client)) == 400
    without = ClientCertificate(str(robot.cert), str(robot.key))
    with pytest.raises(ConfigError, match="is encrypted: set CLIENT_KEY_PASSWORD_FILE"):
        tls.context(TlsOptions(str(ca.pem), without))
    secret.write_text("wrong horse\n")
    with pytest.raises(ConfigError, match="passphrase in CLIENT_KEY_PASSWORD_FILE does not"):
        tls.context(TlsOptions(str(ca.pem), client))


def test_no_client_certificate_is_named_as_the_reason(
    gateway: MutualTlsGateway, ca: CertificateAuthority
) -> None:
    with pytest.raises(EndpointRefusedError) as refused:
        post(gateway.endpoint, TlsOptions(str(ca.pem)))
    assert "requires a client certificate" in str(refused.value)
    assert "CLIENT_CERT" in str(refused.value)


def test_a_client_certificate_from_another_ca_is_named_as_refused(
    tmp_path: Path, gateway: MutualTlsGateway, ca: CertificateAuthority
) -> None:
    stranger = CertificateAuthority(tmp_path / "other", "Other CA").client("robot-x")
    client = ClientCertificate(str(stranger.cert), str(stranger.key))
    with pytest.raises(EndpointRefusedError) as refused:
        post(gateway.endpoint, TlsOptions(str(ca.pem), client))
    assert "refused this robot's client certificate" in str(refused.value)
    # the gateway notes the refusal after its alert reached the client: wait for it
    wait_for(lambda: len(gateway.refused) == 1, 10, "the gateway to note one refusal")


def test_a_server_that_hangs_up_without_an_alert_gets_a_client_certificate_hint(
    stub_factory, ca: CertificateAuthority
) -> None:
    """The stub itself (uvicorn, asyncio) requiring client certificates closes the
    connection without a TLS alert: an outage to the bridge, with the hint."""
    server, tester = ca.server("stub-mtls"), ca.client("the-test")
    stub = stub_factory(
        "--tls-cert",
        str(server.cert),
        "--tls-key",
        str(server.key),
        "--tls-client-ca",
        str(ca.pem),
        client=(tester.cert, tester.key),
    )
    with pytest.raises(TransientSendError) as failed:
        post(stub.endpoint, TlsOptions(str(ca.pem)))
    assert "set CLIENT_CERT and CLIENT_KEY" in str(failed.value)
    robot = ca.client("robot-002")
    client = ClientCertificate(str(robot.cert), str(robot.key))
    assert post(stub.endpoint, TlsOptions(str(ca.pem), client)) == 400  # and served with one


@pytest.mark.parametrize("problem", ["missing", "mismatch", "not-pem"])
def test_a_wrong_client_certificate_is_a_one_line_error_at_start(
    tmp_path: Path, ca: CertificateAuthority, problem: str
) -> None:
    robot, other = ca.client("robot-a"), ca.client("robot-b")
    cert, key = str(robot.cert), str(robot.key)
    if problem == "missing":
        cert = str(tmp_path / "nowhere.pem")
    elif problem == "mismatch":
        key = str(other.key)
    else:
        Path(key).write_text("not a key\n")
    done = run_cli(
        "run",
        timeout=60,
        BRIDGE_INPUT="sim",
        QUEUE_PATH=str(tmp_path / "queue.db"),
        PHYCLOUD_ENDPOINT="https://127.0.0.1:9/api/v1",
        CLIENT_CERT=cert,
        CLIENT_KEY=key,
    )
    assert done.returncode == 2, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, done.stderr
    expected = {
        "missing": "CLIENT_CERT",
        "mismatch": "is not the key of CLIENT_CERT",
        "not-pem": "not a PEM certificate and key",
    }[problem]
    assert expected in lines[0]


def _hashed_dir(tmp_path: Path, ca: CertificateAuthority) -> Path:
    """A c_rehash'ed folder holding the CA, as /etc/ssl/certs is."""
    folder = tmp_path / "certs"
    folder.mkdir()
    shutil.copy(ca.pem, folder / "company.pem")
    subprocess.run(["openssl", "rehash", str(folder)], check=True, timeout=60)
    return folder
