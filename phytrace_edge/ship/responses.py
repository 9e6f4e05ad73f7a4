"""What PhyCloud's answer means for a batch (docs/phycloud-openapi.yaml). Pure.

``classify`` turns a reply into an outcome the sender acts on, or raises the
``TransientSendError`` that tells the retry policy to try again (and how long to
wait, from ``Retry-After``).

A 2xx deletes nothing unless it accounts for every event of the batch (``account``):
accepted + duplicates + rejected == the batch's size, each rejected event named by its
``event_id`` (its ``index`` only confirms it). A count that falls short, a 1-based
index or an event_id PhyCloud made up would otherwise delete events PhyCloud never
took, or dead-letter the wrong ones.

What PhyCloud says is masked *after* it is decoded (``Reply.mask``), before anything
of it is kept (a dead letter's reason) or logged: a server that echoes the request's
Authorization header with JSON escapes (``\\/``, ``\\u002f``) slips past a mask of
the raw bytes.
"""

from __future__ import annotations

import email.utils
import re
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeGuard, TypeVar

import orjson

from phytrace_edge.errors import (
    EndpointRefusedError,
    TransientSendError,
    UnaccountedAnswerError,
    UnexpectedAnswerError,
)

T = TypeVar("T")
Mask = Callable[[str], str]

RETRY_AFTER_MAX_S = 3600.0
RETRYABLE = {408, 425, 429}
SPLIT = {400, 413, 422}
REASON_CHARS = 512  # of a rejected event's reason, as a dead letter keeps it
BODY_CHARS = 4096  # of a refusal's body, as a dead letter keeps it
# PhyCloud's answers nest three deep: what nests deeper is not kept, and masking it
# stays far from Python's recursion limit (orjson reads up to 1024 levels)
MAX_DEPTH = 32
_JSON_ESCAPE = re.compile(r'\\(u[0-9a-fA-F]{4}|["\\/bfnrt])')
_ESCAPED = {'"': '"', "\\": "\\", "/": "/", "b": "\b", "f": "\f", "n": "\n", "r": "\r", "t": "\t"}
_NOT_JSON = object()


def no_mask(text: str) -> str:
    """The mask of a reply that quotes nothing secret (the tests' fake transports)."""
    return text


@dataclass(frozen=True)
class Reply:
    """An HTTP answer: status, headers (lower-case names) and body. ``mask`` hides what
    the answer may quote of the request (the API key) in text decoded from it; the
    transport that sent the key provides it."""

    status: int
    headers: Mapping[str, str]
    body: bytes
    mask: Mask = field(default=no_mask, repr=False, compare=False)


@dataclass(frozen=True)
class Accepted:
    """2xx that accounts for the whole batch: ``rejected`` maps the index in the batch
    of each event PhyCloud refused individually to why."""

    rejected: dict[int, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Refused:
    """400/422/413: the batch as a whole was refused because of its content or size;
    ``index`` is the event PhyCloud blamed, when it said."""

    status: int
    reason: str
    index: int | None = None


Outcome = Accepted | Refused


class Unaccounted(ValueError):
    """What in PhyCloud's answer does not add up (``account``), in one line."""


def parse_retry_after(value: str | None, now: float) -> float | None:
    """Seconds to wait from a Retry-After header (seconds or HTTP-date), capped at an
    hour so a broken header cannot park a robot for days; None when absent or bad."""
    if not value:
        return None
    value = value.strip()
    try:
        seconds = float(value)
    except ValueError:
        try:
            seconds = email.utils.parsedate_to_datetime(value).timestamp() - now
        except (TypeError, ValueError, IndexError, OverflowError):
            return None
    if seconds != seconds:  # NaN
        return None
    return min(max(0.0, seconds), RETRY_AFTER_MAX_S)


def _decoded(body: bytes) -> Any:
    """The JSON value of ``body``, or ``_NOT_JSON``."""
    try:
        return orjson.loads(body) if body else _NOT_JSON
    except orjson.JSONDecodeError:
        return _NOT_JSON


def masked(value: Any, mask: Mask, depth: int = 0) -> Any:
    """Decoded JSON ``value`` with ``mask`` applied to every string in it, keys too;
    lists and objects nested deeper than MAX_DEPTH become None."""
    if isinstance(value, str):
        return mask(value)
    if isinstance(value, list | dict) and depth >= MAX_DEPTH:
        return None
    if isinstance(value, list):
        return [masked(item, mask, depth + 1) for item in value]
    if isinstance(value, dict):
        return {mask(key): masked(item, mask, depth + 1) for key, item in value.items()}
    return value


def _unescape(match: re.Match[str]) -> str:
    code = match.group(1)
    if code[0] != "u":
        return _ESCAPED[code]
    char = chr(int(code[1:], 16))
    # a lone surrogate cannot be stored as UTF-8 (and a key is ASCII): left escaped
    return match.group(0) if "\ud800" <= char <= "\udfff" else char


def masked_text(text: str, mask: Mask) -> str:
    """Text that is not JSON (an HTML page, an answer cut at 64 KiB) masked as it is,
    and with its JSON escapes decoded when they spell what ``mask`` hides."""
    plain = mask(text)
    unescaped = _JSON_ESCAPE.sub(_unescape, plain)
    again = mask(unescaped)
    return again if again != unescaped else plain


def kept_body(body: bytes, mask: Mask) -> str:
    """A refusal's body as a dead letter keeps it: masked once decoded (JSON: every
    string in it, then encoded again), at most BODY_CHARS."""
    document = _decoded(body)
    if document is not _NOT_JSON:
        try:
            return orjson.dumps(masked(document, mask)).decode()[:BODY_CHARS]
        except orjson.JSONEncodeError:
            pass  # kept as text instead
    return masked_text(body.decode("utf-8", "replace"), mask)[:BODY_CHARS]


def is_contract_answer(document: dict[str, Any]) -> bool:
    """Whether a 2xx body is PhyCloud's answer (docs/phycloud-api.md): a JSON object with
    the count of events ``accepted``. A captive portal's page, a proxy's banner or an
    empty 200 is not, and must not make the bridge delete a batch."""
    accepted = document.get("accepted")
    rejected = document.get("rejected", [])
    return _whole(accepted) and isinstance(rejected, list)


def _whole(value: Any) -> TypeGuard[int]:
    """A count or an index: an integer (not a bool) >= 0."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _shown(value: Any, mask: Mask) -> str:
    """A value of the answer as a message quotes it: masked (before it is cut, so no
    piece of a key is left), short, on one line (repr escapes line breaks)."""
    return repr(masked(value, mask))[:60]


def account(
    answer: Mapping[str, Any], event_ids: Sequence[str], mask: Mask = no_mask
) -> dict[int, str]:
    """The events PhyCloud's answer rejects (index in the batch -> reason, masked), if
    the answer accounts for every event of the batch of ``event_ids``: ``accepted`` +
    ``duplicates`` (absent: 0) + the ``rejected`` items == the batch's size, and each
    item names an event of the batch by its ``event_id``, no event twice. An item's
    ``index``, when given, must be the same event's (the cross-check that catches a
    1-based index); only an event without an event_id is named by its index alone.
    Raises ``Unaccounted`` saying what does not add up (what it quotes, masked)."""
    size = len(event_ids)
    accepted = answer["accepted"]
    duplicates = answer.get("duplicates")
    duplicates = 0 if duplicates is None else duplicates
    if not _whole(duplicates):
        shown = _shown(duplicates, mask)
        raise Unaccounted(f"PhyCloud's answer has duplicates {shown}, not a count")
    items = answer.get("rejected") or []
    total = accepted + duplicates + len(items)
    if total != size:
        raise Unaccounted(
            f"PhyCloud's answer accounts for {total} of {size} events (accepted {accepted}, "
            f"duplicates {duplicates}, rejected {len(items)})"
        )
    positions: dict[str, list[int]] = {}
    for position, event_id in enumerate(event_ids):
        positions.setdefault(event_id, []).append(position)
    rejected: dict[int, str] = {}
    for n, item in enumerate(items):
        position = _rejected_position(n, item, event_ids, positions, rejected, mask)
        reason = item.get("reason")
        text = mask(reason) if isinstance(reason, str) else "rejected"
        rejected[position] = text[:REASON_CHARS]  # masked before the cut: no piece of a key
    return rejected


def _rejected_position(
    n: int,
    item: Any,
    event_ids: Sequence[str],
    positions: Mapping[str, list[int]],
    taken: Collection[int],
    mask: Mask,
) -> int:
    """The index in the batch of the event ``rejected[n]`` names (``account``)."""
    where = f"PhyCloud's answer's rejected[{n}]"
    if not isinstance(item, dict):
        raise Unaccounted(f"{where} is not an object")
    event_id, index = item.get("event_id"), item.get("index")
    if event_id is not None and not isinstance(event_id, str):
        raise Unaccounted(f"{where} has event_id {_shown(event_id, mask)}, not text")
    if index is not None and not (_whole(index) and index < len(event_ids)):
        shown = _shown(index, mask)
        raise Unaccounted(f"{where} has index {shown}, not one of 0..{len(event_ids) - 1}")
    named = f"event_id {_shown(event_id, mask)}" if event_id else f"index {index}"
    if event_id and event_id not in positions:
        raise Unaccounted(f"{where} names {named}, not an event of the batch")
    if index is not None:
        if event_ids[index] != (event_id or ""):
            given = named if event_id else "no event_id"
            raise Unaccounted(f"{where} gives index {index} with {given}: not the event there")
        position = index
    elif event_id:
        position = next((p for p in positions[event_id] if p not in taken), -1)
    else:
        raise Unaccounted(f"{where} names no event (neither event_id nor index)")
    if position < 0 or position in taken:
        raise Unaccounted(f"{where} rejects {named} a second time")
    return position


def classify(reply: Reply, event_ids: Sequence[str], now: float) -> Outcome:
    """The outcome of ``reply`` for the batch of ``event_ids`` (in the order sent), or
    raise the error to retry on."""
    status = reply.status
    if 200 <= status < 300:
        document = _decoded(reply.body)
        if not isinstance(document, dict) or not is_contract_answer(document):
            kind = reply.headers.get("content-type", "no content type").split(";")[0]
            raise UnexpectedAnswerError(
                f"HTTP {status} without PhyCloud's answer ({reply.mask(kind)[:80]}, "
                f"{len(reply.body)} bytes) - a captive portal or proxy in the way? Kept the batch",
                status,
            )
        try:
            return Accepted(account(document, event_ids, reply.mask))
        except Unaccounted as exc:
            raise UnaccountedAnswerError(f"{exc} - kept the batch", status) from None
    if status in SPLIT:
        document = _decoded(reply.body)
        if status != 413 and not isinstance(document, dict):
            # PhyCloud's 400/422 is a JSON document; an HTML page is a gateway's (one that
            # wants a client certificate answers so): no event is to blame for it
            kind = reply.headers.get("content-type", "no content type").split(";")[0]
            raise UnexpectedAnswerError(
                f"HTTP {status} without PhyCloud's answer ({reply.mask(kind)[:80]}, "
                f"{len(reply.body)} bytes) - a proxy or gateway in the way (one that "
                "requires a client certificate answers so)? Kept the batch",
                status,
            )
        index = document.get("index") if isinstance(document, dict) else None
        valid_index = _whole(index) and index < len(event_ids)
        return Refused(status, kept_body(reply.body, reply.mask), index if valid_index else None)
    retry_after = parse_retry_after(reply.headers.get("retry-after"), now)
    if status in RETRYABLE or 500 <= status < 600:
        raise TransientSendError(f"HTTP {status}", status, retry_after)
    if status in (401, 403):
        raise EndpointRefusedError(
            f"HTTP {status}: PhyCloud refused the API key - check PHYCLOUD_API_KEY", status
        )
    if status == 415:
        raise EndpointRefusedError(
            "HTTP 415: PhyCloud does not accept this Content-Encoding - set HTTP_COMPRESSION=gzip",
            status,
        )
    raise EndpointRefusedError(
        f"HTTP {status}: unexpected answer from PhyCloud - check PHYCLOUD_ENDPOINT", status
    )


def split_refused(events: Sequence[T], refused: Refused) -> list[Sequence[T]]:
    """Parts to resend: around the event PhyCloud blamed, else two halves."""
    if refused.index is not None and refused.status != 413:
        i = refused.index
        return [part for part in (events[:i], events[i : i + 1], events[i + 1 :]) if part]
    middle = len(events) // 2
    return [events[:middle], events[middle:]]
