"""Which proxy, if any, carries the requests to PhyCloud. Pure.

As curl and every shipper do: ``https_proxy``/``HTTPS_PROXY`` for an https endpoint,
``http_proxy``/``HTTP_PROXY`` for http, ``all_proxy``/``ALL_PROXY`` for either, and
``no_proxy``/``NO_PROXY`` to go direct (hosts, their subdomains, IPs, CIDR, ``*``); the
lower-case name wins, as in the standard library. The ``PHYCLOUD_PROXY`` setting
overrides the environment for the bridge alone (``direct``: never a proxy). An https
endpoint is reached through a CONNECT tunnel: the proxy sees the host name, never the
request or its key. Proxy credentials come from the URL (``http://user:pass@proxy``)
and are masked wherever the URL is shown.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Mapping
from urllib.parse import urlsplit

from phytrace_edge.errors import ConfigError
from phytrace_edge.redact import redact_url

DIRECT = "direct"
PROXY_SCHEMES = ("http", "https")


def proxy_for(endpoint: str, env: Mapping[str, str], setting: str | None = None) -> str | None:
    """The proxy URL for requests to ``endpoint``, or None to connect directly."""
    if setting is not None:
        return None if setting.strip().lower() == DIRECT else _checked(setting, "PHYCLOUD_PROXY")
    proxies = _environment_proxies(env)
    parts = urlsplit(endpoint)
    if bypassed(parts.hostname or "", proxies.get("no", "")):
        return None
    for scheme in (parts.scheme, "all"):
        if proxies.get(scheme):
            return _checked(proxies[scheme], f"{scheme}_proxy")
    return None


def bypassed(host: str, no_proxy: str) -> bool:
    """Whether NO_PROXY sends ``host`` direct: ``*``, the host itself, a domain it is
    in (``example.com`` or ``.example.com``), its IP address, or a network (CIDR) that
    holds it - curl's rules."""
    host = host.strip("[]").lower().rstrip(".")
    for entry in (e.strip().lower().rstrip(".") for e in no_proxy.split(",")):
        if not entry:
            continue
        if entry == "*" or host == entry.lstrip(".") or host.endswith("." + entry.lstrip(".")):
            return True
        if _in_network(host, entry):
            return True
    return False


def _in_network(host: str, entry: str) -> bool:
    try:
        return ipaddress.ip_address(host) in ipaddress.ip_network(entry.strip("[]"), strict=False)
    except ValueError:
        return False


def _environment_proxies(env: Mapping[str, str]) -> dict[str, str]:
    """``{scheme: url}`` from ``env``, lower-case names winning (the standard library's
    rule for the process environment, applied to the mapping given)."""
    found: dict[str, str] = {}
    for name in sorted(env, key=lambda n: n.islower()):  # upper-case first, then lower
        if name.lower().endswith("_proxy") and env[name]:
            found[name[:-6].lower()] = env[name]
    return found


def _checked(url: str, name: str) -> str:
    """``url`` as a proxy URL (``host:port`` gets ``http://``, as curl does)."""
    url = url.strip()
    if "://" not in url:
        url = f"http://{url}"
    parts = urlsplit(url)
    if parts.scheme not in PROXY_SCHEMES or not parts.hostname:
        raise ConfigError(
            f"{name} {redact_url(url)}: not a proxy this bridge can use "
            "(http://host:port or https://host:port)"
        )
    try:
        parts.port  # noqa: B018 - a bad port raises here, not at the first request
    except ValueError:
        raise ConfigError(f"{name} {redact_url(url)}: the port is not a number") from None
    return url
