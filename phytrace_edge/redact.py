"""The API key as a value that never shows itself, and the forms it could leak in.

``Secret`` hides the key from every repr, str, log line and exception. ``leak_forms``
lists the ways a key can still appear in text that quotes it indirectly (escaped in a
repr or in JSON, percent-encoded in a URL), so a redaction filter can catch those too.
"""

from __future__ import annotations

import json
from urllib.parse import urlsplit, urlunsplit

MASK = "***"


class Secret:
    """A string that never shows itself in a repr, str, log line or exception."""

    __slots__ = ("_value",)

    def __init__(self, value: str) -> None:
        self._value = value

    def reveal(self) -> str:
        """The real value, for the one place that must send it (the HTTP header)."""
        return self._value

    def __bool__(self) -> bool:
        return bool(self._value)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Secret) and other._value == self._value

    def __hash__(self) -> int:
        return hash(self._value)

    def __str__(self) -> str:
        return MASK if self._value else ""

    def __repr__(self) -> str:
        return f"Secret({str(self)!r})"


def leak_forms(secret: str) -> list[str]:
    """Every form of ``secret`` worth masking, longest first: as is, as Python's repr
    and JSON escape it, and percent-encoded."""
    from urllib.parse import quote

    if not secret:
        return []
    forms = {
        secret,
        repr(secret)[1:-1],
        json.dumps(secret)[1:-1],
        secret.encode("unicode_escape").decode("ascii"),
        quote(secret, safe=""),
    }
    return sorted(forms, key=len, reverse=True)


def redact(text: str, forms: list[str]) -> str:
    """``text`` with each of ``forms`` (from ``leak_forms``) replaced by ``***``."""
    for form in forms:
        text = text.replace(form, MASK)
    return text


class _Known:
    """The secrets this process holds (the API key, and every key rotated in since),
    so that the log filter masks a key read from a file after logging was set up."""

    def __init__(self) -> None:
        self.forms: list[str] = []

    def remember(self, secret: str) -> None:
        if len(secret) < 4:  # too short to mask without masking ordinary words
            return
        fresh = set(leak_forms(secret)) - set(self.forms)
        if fresh:
            self.forms = sorted({*self.forms, *fresh}, key=len, reverse=True)


KNOWN = _Known()


def remember(secret: str) -> None:
    """Mask ``secret`` (every form of it) in every log record from now on."""
    KNOWN.remember(secret)


def redact_url(url: str) -> str:
    """``url`` with the credentials in it masked: ``user:***@`` (a user name alone may
    be a token itself: ``***@``). Whatever cannot be parsed loses all before the ``@``."""
    try:
        parts = urlsplit(url)
        userinfo, at, hostport = parts.netloc.rpartition("@")
    except ValueError:
        scheme, slashes, rest = url.rpartition("//")
        return scheme + slashes + ("***@" + rest.rpartition("@")[2] if "@" in rest else rest)
    if not at:
        return url
    user, colon, _ = userinfo.partition(":")
    masked = f"{user}:***" if colon else "***"
    return urlunsplit(parts._replace(netloc=f"{masked}@{hostport}"))
