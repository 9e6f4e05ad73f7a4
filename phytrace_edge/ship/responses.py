"""What PhyCloud's answer means for a batch (docs/phycloud-openapi.yaml). Pure.

``classify`` turns a reply into an outcome the sender acts on, or raises the
``TransientSendError`` that tells the retry policy to try again (and how long to
wait, from ``Retry-After``).
"""

from __future__ import annotations

import email.utils
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import orjson

from phytrace_edge.errors import EndpointRefusedError, TransientSendError, UnexpectedAnswerError

T = TypeVar("T")

RETRY_AFTER_MAX_S = 3600.0
RETRYABLE = {408, 425, 429}
SPLIT = {400, 413, 422}


@dataclass(frozen=True)
class Reply:
    """An HTTP answer: status, headers (lower-case names) and body."""

    status: int
    headers: Mapping[str, str]
    body: bytes


@dataclass(frozen=True)
class Accepted:
    """2xx: the batch is in; ``rejected`` maps an event's index to why it was refused."""

    rejected: dict[int, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Refused:
    """400/422/413: the batch as a whole was refused because of its content or size;
    ``index`` is the event PhyCloud blamed, when it said."""

    status: int
    reason: str
    index: int | None = None


Outcome = Accepted | Refused


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


def _document(body: bytes) -> dict[str, Any]:
    try:
        document = orjson.loads(body) if body else {}
    except orjson.JSONDecodeError:
        return {}
    return document if isinstance(document, dict) else {}


def _text(body: bytes) -> str:
    return body[:4096].decode("utf-8", "replace")


def is_contract_answer(document: dict[str, Any]) -> bool:
    """Whether a 2xx body is PhyCloud's answer (docs/phycloud-api.md): a JSON object with
    the count of events ``accepted``. A captive portal's page, a proxy's banner or an
    empty 200 is not, and must not make the bridge delete a batch."""
    accepted = document.get("accepted")
    rejected = document.get("rejected", [])
    return (
        isinstance(accepted, int)
        and not isinstance(accepted, bool)
        and accepted >= 0
        and isinstance(rejected, list)
    )


def classify(reply: Reply, batch_size: int, now: float) -> Outcome:
    """The outcome of ``reply`` for a batch of ``batch_size`` events, or raise the
    error to retry on."""
    status = reply.status
    if 200 <= status < 300:
        document = _document(reply.body)
        if not is_contract_answer(document):
            kind = reply.headers.get("content-type", "no content type").split(";")[0]
            raise UnexpectedAnswerError(
                f"HTTP {status} without PhyCloud's answer ({kind}, {len(reply.body)} bytes) - "
                "a captive portal or proxy in the way? Kept the batch",
                status,
            )
        rejected = {}
        for item in document.get("rejected") or []:
            index = item.get("index") if isinstance(item, dict) else None
            if isinstance(index, int) and 0 <= index < batch_size:
                rejected[index] = str(item.get("reason", "rejected"))[:512]
        return Accepted(rejected)
    if status in SPLIT:
        document = _document(reply.body)
        index = document.get("index")
        valid_index = isinstance(index, int) and 0 <= index < batch_size
        return Refused(status, _text(reply.body), index if valid_index else None)
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
