"""The API key and where it comes from.

A key given in the environment (``PHYCLOUD_API_KEY``) is fixed for the life of the
process. A key in a file (``PHYCLOUD_API_KEY_FILE``, or systemd's credential
``$CREDENTIALS_DIRECTORY/phycloud_api_key``) can be rotated without a restart: the
transport reads the file again when PhyCloud refuses the key, and the service on
SIGHUP. The key itself never leaves this object except into the request header
(``Secret``); every key it ever held stays in ``leak_forms``, so text that quotes an
old key is still masked.
"""

from __future__ import annotations

import logging
import os
import re
import stat
import threading
from pathlib import Path

from phytrace_edge.errors import ConfigError
from phytrace_edge.redact import Secret, leak_forms, remember

log = logging.getLogger(__name__)

KEY_FILE_MAX_BYTES = 8192
CREDENTIAL_NAME = "phycloud_api_key"  # LoadCredential=phycloud_api_key:/etc/...
_PRINTABLE = re.compile(r"[\x21-\x7e]{1,4096}")  # as the PHYCLOUD_API_KEY setting


def read_key_file(path: str, origin: str) -> Secret:
    """The key in ``path`` (surrounding whitespace and a final newline ignored); a
    one-line ConfigError naming ``origin`` and never the file's contents otherwise."""
    try:
        with Path(path).open("rb") as handle:
            if not stat.S_ISREG(os.fstat(handle.fileno()).st_mode):
                raise ConfigError(f"{origin} {path}: not a regular file")
            raw = handle.read(KEY_FILE_MAX_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{origin} {path}: cannot be read ({exc.strerror})") from None
    if len(raw) > KEY_FILE_MAX_BYTES:
        raise ConfigError(f"{origin} {path}: larger than an API key can be")
    try:
        text = raw.decode("ascii").strip()
    except UnicodeDecodeError:
        text = None
    if not text:
        reason = "is empty" if text == "" else "is not ASCII text"
        raise ConfigError(f"{origin} {path}: {reason}")
    if not _PRINTABLE.fullmatch(text):
        raise ConfigError(
            f"{origin} {path}: holds characters an API key cannot have "
            "(printable ASCII without spaces, one line)"
        )
    return Secret(text)


def readable_by_others(path: str) -> str | None:
    """A warning when the file at ``path`` can be read by other users, else None."""
    try:
        mode = stat.S_IMODE(Path(path).stat().st_mode)
    except OSError:
        return None
    if mode & 0o044 == 0:
        return None
    return (
        f"{path} holds the API key and is readable by other users (mode {mode:04o}): "
        f"chmod 600 {path}"
    )


class ApiKey:
    """The key to send, and (for a file) how to read it again."""

    def __init__(
        self, value: Secret, path: str | None = None, origin: str = "PHYCLOUD_API_KEY"
    ) -> None:
        self._value = value
        self.path = path
        self.origin = origin  # the setting an operator must fix, named in messages
        self._forms = leak_forms(value.reveal())
        remember(value.reveal())  # masked in every log record from now on
        self._lock = threading.Lock()

    @classmethod
    def from_file(cls, path: str, origin: str) -> ApiKey:
        return cls(read_key_file(path, origin), path, origin)

    @property
    def secret(self) -> Secret:
        return self._value

    @property
    def leak_forms(self) -> list[str]:
        """The forms of every key held since the start (an old one may be echoed)."""
        return self._forms

    @property
    def where(self) -> str:
        """Where the key comes from, for messages: ``PHYCLOUD_API_KEY_FILE /etc/...``."""
        return self.origin if self.path is None else f"{self.origin} {self.path}"

    def reload(self) -> bool:
        """Read the file again; True when the key changed. A key from the environment
        never changes; a file that cannot be read now keeps the key held (and says
        so), since a half-written rotation must not stop delivery."""
        if self.path is None:
            return False
        try:
            fresh = read_key_file(self.path, self.origin)
        except ConfigError as exc:
            log.error("%s; keeping the key read before", exc)
            return False
        with self._lock:
            if fresh == self._value:
                return False
            self._value = fresh
            remember(fresh.reveal())
            self._forms = sorted(
                set(self._forms) | set(leak_forms(fresh.reveal())), key=len, reverse=True
            )
        return True

    def reload_on_hangup(self) -> str:
        """Read the file again because an operator asked (SIGHUP); the line to log."""
        if self.path is None:
            return (
                f"SIGHUP: the API key comes from {self.origin}, which a running process "
                "cannot read again - restart the service to change it"
            )
        changed = self.reload()
        outcome = "a new key, sent from the next request" if changed else "unchanged"
        return f"SIGHUP: read the API key again from {self.where}: {outcome}"
