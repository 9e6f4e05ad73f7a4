"""Text from the robot made safe for JSON, where a handler or the generic converter
takes a string from a message (docs/udm.md, "General rules").

A Python ``str`` can hold what UTF-8 cannot: lone surrogates (U+D800..U+DFFF). They
come from JSON escapes (``"\\ud800"`` is valid JSON), from bytes decoded with
``surrogateescape``, from a surrogate pair written as two code points. orjson refuses
such a string when the queue writer encodes the event, and the whole group of events
being written with it is lost. So each string is repaired on the way in: a lone
surrogate becomes U+FFFD, a pair the one character it stands for, and the caller
learns that it happened, to count it (``TEXT_REPAIRED``). The message is kept: a
repaired string is worth more than a lost event.

Every handler runs for every message, so a string that is fine costs one ``isascii``
(a flag CPython keeps: constant time) or, when not ASCII, one UTF-8 encode in C.
"""

from __future__ import annotations

from typing import Any

# The reason counted, per topic, for a message whose text had to be repaired.
TEXT_REPAIRED = "text_repaired"


def safe_str(value: str) -> tuple[str, bool]:
    """``value`` with what UTF-8 cannot carry replaced by U+FFFD, and whether anything
    was; an exact ``str`` comes back as it is when nothing was."""
    if value.isascii():
        return value, False
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return _repaired(value), True
    return value, False


def _repaired(value: str) -> str:
    # UTF-16 with surrogatepass writes every code unit as it is; reading it back joins
    # the surrogates that form a pair and makes each lone one U+FFFD
    return value.encode("utf-16-le", "surrogatepass").decode("utf-16-le", "replace")


def safe_bytes(value: bytes | bytearray) -> tuple[str, bool]:
    """UTF-8 bytes as text, what is not UTF-8 replaced by U+FFFD; and whether anything
    was (encoded surrogates count as not UTF-8, as Python's codec says)."""
    try:
        return bytes(value).decode("utf-8"), False
    except UnicodeDecodeError:
        return bytes(value).decode("utf-8", "replace"), True


def safe_json(document: Any) -> tuple[Any, int]:
    """A parsed JSON document with every string repaired by ``safe_str``, dict keys
    included, and how many strings were. Dicts and lists are repaired in place (the
    caller's own, just parsed) and walked without recursion: a document as deep as
    the parser allows costs no stack."""
    if isinstance(document, str):
        text, repaired = safe_str(document)
        return text, int(repaired)
    count = 0
    pending = [document]
    while pending:
        node = pending.pop()
        if isinstance(node, list):
            for index, item in enumerate(node):
                if isinstance(item, str):
                    text, repaired = safe_str(item)
                    if repaired:
                        node[index], count = text, count + 1
                elif isinstance(item, (dict, list)):
                    pending.append(item)
        elif isinstance(node, dict):
            count += _repair_dict(node, pending)
    return document, count


def _repair_dict(node: dict[Any, Any], pending: list[Any]) -> int:
    """Repair the keys and string values of one dict in place (its order kept); queue
    its containers on ``pending``; the number of strings repaired."""
    count = 0
    entries = []
    for key, value in node.items():
        if isinstance(key, str):
            key, repaired = safe_str(key)
            count += repaired
        if isinstance(value, str):
            value, repaired = safe_str(value)
            count += repaired
        elif isinstance(value, (dict, list)):
            pending.append(value)
        entries.append((key, value))
    if count:  # rebuilt only when something changed: a repaired key is a new key
        node.clear()
        node.update(entries)
    return count
