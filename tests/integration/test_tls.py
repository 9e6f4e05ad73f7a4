"""TLS is verified by default; CA_BUNDLE adds a private CA; an untrusted certificate is
reported as a configuration problem (kept data, long backoff), not retried quietly."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from phytrace_edge.config import load_settings
from phytrace_edge.errors import EndpointRefusedError
from phytrace_edge.redact import Secret
from phytrace_edge.ship.transport import HttpTransport


def openssl(*args: str) -> None:
    subprocess.run(["openssl", *args], check=True, capture_output=True, timeout=60)


@pytest.fixture(scope="module")
def certificates(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A throwaway CA and a server certificate for 127.0.0.1 signed by it."""
    folder = tmp_path_factory.mktemp("tls")
    ca_key, ca, key, csr, cert = (
        folder / n for n in ("ca.key", "ca.pem", "server.key", "server.csr", "server.pem")
    )
    openssl(
        "req",
        "-x509",
        "-newkey",
        "rsa:2048",
        "-nodes",
        "-days",
        "2",
        "-subj",
        "/CN=test-ca",
        "-keyout",
        str(ca_key),
        "-out",
        str(ca),
    )
    openssl(
        "req",
        "-newkey",
        "rsa:2048",
        "-nodes",
        "-subj",
        "/CN=127.0.0.1",
        "-keyout",
        str(key),
        "-out",
        str(csr),
    )
    extensions = folder / "san.cnf"
    extensions.write_text("subjectAltName=IP:127.0.0.1\n")
    openssl(
        "x509",
        "-req",
        "-in",
        str(csr),
        "-CA",
        str(ca),
        "-CAkey",
        str(ca_key),
        "-CAcreateserial",
        "-days",
        "2",
        "-extfile",
        str(extensions),
        "-out",
        str(cert),
    )
    return {"ca": ca, "cert": cert, "key": key}


def test_private_ca_needs_ca_bundle(stub_factory, certificates) -> None:
    stub = stub_factory(
        "--tls-cert", str(certificates["cert"]), "--tls-key", str(certificates["key"])
    )
    assert stub.endpoint.startswith("https://")
    body, headers = b'{"events": []}', {"Content-Type": "application/json"}

    untrusted = HttpTransport(stub.endpoint, Secret("k"), timeout_s=10)
    with pytest.raises(EndpointRefusedError, match="set CA_BUNDLE"):
        untrusted.post_events(body, headers)
    untrusted.close()

    settings = load_settings(
        env={"CA_BUNDLE": str(certificates["ca"]), "PHYCLOUD_ENDPOINT": stub.endpoint}
    ).settings
    trusted = HttpTransport(
        settings.phycloud_endpoint, Secret("k"), timeout_s=10, ca_bundle=settings.ca_bundle
    )
    assert trusted.post_events(body, headers).status == 400  # reached the stub: empty batch
    trusted.close()
