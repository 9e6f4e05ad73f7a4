"""Whom the bridge trusts, who it says it is, and what a failed handshake means.

Trust (the rule ``docs/configuration.md`` states): the system's trust store, as
OpenSSL finds it (``/etc/ssl/certs`` on Debian and Ubuntu; ``SSL_CERT_FILE`` and
``SSL_CERT_DIR`` move it, as for curl), so a company CA installed with
``update-ca-certificates`` is trusted; ``CA_BUNDLE`` adds its CAs to those. Only where
the system has no store at all (a bare container) are certifi's CAs used instead.

Identity: ``CLIENT_CERT`` and ``CLIENT_KEY`` (PEM) for a server that asks for a
client certificate, the key's passphrase from ``CLIENT_KEY_PASSWORD_FILE``; checked at
start, so a wrong file is a one-line error and not a failed handshake an hour later.
"""

from __future__ import annotations

import logging
import os
import ssl
from dataclasses import dataclass
from pathlib import Path

from phytrace_edge.errors import ConfigError

log = logging.getLogger(__name__)

EXPIRY_WARNING_S = 14 * 86400  # status warns this long before CLIENT_CERT expires

# What OpenSSL's verification codes mean for an operator (X509_V_ERR_*)
_UNTRUSTED_ISSUER = {2, 18, 19, 20, 21}
_EXPIRED, _NOT_YET_VALID = 10, 9
_NAME_MISMATCH = {62, 64}  # a host name, an IP address
# TLS alerts a server sends when it refuses the client's certificate (or its absence)
_CLIENT_CERT_ALERTS = (
    "CERTIFICATE_REQUIRED",
    "BAD_CERTIFICATE",
    "UNKNOWN_CA",
    "CERTIFICATE_EXPIRED",
    "CERTIFICATE_REVOKED",
    "CERTIFICATE_UNKNOWN",
    "UNSUPPORTED_CERTIFICATE",
    "ACCESS_DENIED",
)


@dataclass(frozen=True)
class ClientCertificate:
    """CLIENT_CERT, CLIENT_KEY (None: the key is in the cert's file) and
    CLIENT_KEY_PASSWORD_FILE."""

    cert: str
    key: str | None = None
    password_file: str | None = None


@dataclass(frozen=True)
class TlsOptions:
    """CA_BUNDLE and the client certificate."""

    ca_bundle: str | None = None
    client: ClientCertificate | None = None


def system_store() -> str | None:
    """The trust store OpenSSL would use here (after SSL_CERT_FILE/SSL_CERT_DIR), or
    None when the system has none."""
    paths = ssl.get_default_verify_paths()
    for found in (paths.cafile, paths.capath):
        if found and Path(found).exists():
            return found
    return None


def context(options: TlsOptions) -> ssl.SSLContext:
    """The client context: system trust (else certifi's), CA_BUNDLE added, the client
    certificate loaded; a ConfigError names the setting that is wrong."""
    ctx = ssl.create_default_context()  # OpenSSL's default paths: the system store
    if system_store() is None:
        import certifi  # httpx's own dependency

        log.info("no system trust store found; trusting certifi's CAs")
        ctx.load_verify_locations(cafile=certifi.where())
    if options.ca_bundle:
        try:
            ctx.load_verify_locations(cafile=options.ca_bundle)
        except (OSError, ssl.SSLError) as exc:
            raise ConfigError(
                f"CA_BUNDLE={options.ca_bundle!r}: not a usable CA file ({exc})"
            ) from None
    if options.client is not None:
        load_client_certificate(ctx, options.client)
    return ctx


def load_client_certificate(ctx: ssl.SSLContext, client: ClientCertificate) -> None:
    """Load CLIENT_CERT/CLIENT_KEY into ``ctx``, or a one-line ConfigError."""
    for name, path in (
        ("CLIENT_CERT", client.cert),
        ("CLIENT_KEY", client.key),
        ("CLIENT_KEY_PASSWORD_FILE", client.password_file),
    ):
        if path is not None and not os.access(path, os.R_OK):
            reason = "does not exist" if not Path(path).exists() else "cannot be read"
            raise ConfigError(f"{name} {path}: {reason}")
    password = _password(client.password_file)
    try:  # a callable, always: else OpenSSL would prompt on a terminal for a passphrase
        ctx.load_cert_chain(client.cert, client.key, password=lambda: password)
    except ssl.SSLError as exc:
        raise ConfigError(_load_error(client, exc)) from None
    except OSError as exc:
        raise ConfigError(f"CLIENT_CERT {client.cert}: cannot be read ({exc.strerror})") from None


def _password(path: str | None) -> bytes:
    if path is None:
        return b""
    return Path(path).read_bytes()[:4096].rstrip(b"\r\n")


def _load_error(client: ClientCertificate, exc: ssl.SSLError) -> str:
    reason = exc.reason or str(exc)  # "[SSL] PEM lib" comes without a reason
    key = client.key or client.cert
    if reason == "KEY_VALUES_MISMATCH":
        return f"CLIENT_KEY {key} is not the key of CLIENT_CERT {client.cert}"
    if _encrypted(key):
        if client.password_file is None:
            return (
                f"CLIENT_KEY {key} is encrypted: set CLIENT_KEY_PASSWORD_FILE to the file "
                "holding its passphrase"
            )
        return f"CLIENT_KEY {key}: the passphrase in CLIENT_KEY_PASSWORD_FILE does not open it"
    if reason in ("NO_START_LINE", "NO_CERTIFICATE_OR_CRL_FOUND") or "PEM lib" in reason:
        return f"CLIENT_CERT {client.cert} / CLIENT_KEY {key}: not a PEM certificate and key"
    return f"CLIENT_CERT {client.cert} / CLIENT_KEY {key}: cannot be used ({reason})"


def _encrypted(key_file: str) -> bool:
    """Whether a PEM key file holds an encrypted key (PKCS#8 or OpenSSL's old form)."""
    try:
        return b"ENCRYPTED" in Path(key_file).read_bytes()[:65536]
    except OSError:
        return False


def certificate_expiry(path: str) -> float:
    """When the first certificate in ``path`` expires (Unix seconds)."""
    from cryptography import x509  # only when a client certificate is set

    certificate = x509.load_pem_x509_certificate(Path(path).read_bytes())
    return certificate.not_valid_after_utc.timestamp()


def handshake_failure(exc: BaseException, host: str, client_cert: bool) -> str | None:
    """What a failed TLS handshake means, in words an operator can act on; None when
    ``exc`` is no TLS failure. The cause is searched for along the exception's chain
    (httpx wraps the ssl module's error)."""
    cause: BaseException | None = exc
    while cause is not None:
        if isinstance(cause, ssl.SSLCertVerificationError):
            return _verification_failure(cause, host)
        if isinstance(cause, ssl.SSLError):
            reason = cause.reason or str(cause)
            if any(alert in reason for alert in _CLIENT_CERT_ALERTS):
                return _client_certificate_refused(reason, host, client_cert)
            return None
        cause = cause.__cause__ or cause.__context__
    return None


def _verification_failure(exc: ssl.SSLCertVerificationError, host: str) -> str:
    code, message = exc.verify_code, exc.verify_message
    if code in _UNTRUSTED_ISSUER:
        return (
            f"TLS: the certificate of {host} is signed by a CA this robot does not trust "
            f"({message}) - install that CA in the system store (update-ca-certificates) "
            "or set CA_BUNDLE to it"
        )
    if code in _NAME_MISMATCH:
        return (
            f"TLS: the certificate presented is not for {host} ({message}) - check "
            "PHYCLOUD_ENDPOINT, or a proxy that intercepts TLS"
        )
    if code == _EXPIRED:
        return (
            f"TLS: the certificate of {host} has expired ({message}) - "
            "or this robot's clock is wrong"
        )
    if code == _NOT_YET_VALID:
        return (
            f"TLS: the certificate of {host} is not valid yet ({message}) - "
            "is this robot's clock right?"
        )
    return f"TLS: the certificate of {host} did not verify ({message})"


def _client_certificate_refused(reason: str, host: str, client_cert: bool) -> str:
    if not client_cert:
        return (
            f"TLS: {host} requires a client certificate ({reason}) - set CLIENT_CERT and CLIENT_KEY"
        )
    return f"TLS: {host} refused this robot's client certificate CLIENT_CERT ({reason})"
