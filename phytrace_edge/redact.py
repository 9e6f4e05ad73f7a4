"""The API key as a value that never shows itself, and the forms it could leak in.

``Secret`` hides the key from every repr, str, log line and exception. ``leak_forms``
lists the ways a key can still appear in text that quotes it indirectly (escaped in a
repr or in JSON, percent-encoded in a URL), so a redaction filter can catch those too.
"""

from __future__ import annotations

import json

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
