"""PhyCloud's answers at their edges (ship/responses.py): what is PhyCloud's answer and
what is not, how a refusal too large is split, a refusal's body in bytes that are not
UTF-8, and the key masked wherever an answer may quote it (inside lists, at the depth
kept, behind JSON escapes, beside lone surrogates, in what an unaccounted answer says)."""

from __future__ import annotations

import orjson
import pytest

from phytrace_edge.errors import UnaccountedAnswerError, UnexpectedAnswerError
from phytrace_edge.redact import leak_forms, redact
from phytrace_edge.ship.responses import (
    MAX_DEPTH,
    Accepted,
    Refused,
    Reply,
    classify,
    kept_body,
    masked,
    masked_text,
    split_refused,
)

NOW = 1_800_000_000.0
KEY = "phk_live/Zq8v2+K9x7/Lw3"


def mask(text: str) -> str:
    """As the transport masks what PhyCloud says."""
    return redact(text, leak_forms(KEY))


def test_a_2xx_without_rejected_is_an_answer_that_rejects_nothing() -> None:
    body = orjson.dumps({"accepted": 2, "duplicates": 0})
    assert classify(Reply(200, {}, body), ["e0", "e1"], NOW) == Accepted({})


@pytest.mark.parametrize(
    "document",
    [
        {"accepted": 2, "rejected": "none"},  # rejected is a list or absent
        {"accepted": "all", "rejected": []},  # accepted is a count
        {"accepted": -1, "rejected": []},
        {"rejected": []},
    ],
)
def test_a_2xx_that_is_not_phyclouds_answer_deletes_nothing(document: dict) -> None:
    with pytest.raises(UnexpectedAnswerError, match="without PhyCloud's answer"):
        classify(Reply(200, {}, orjson.dumps(document)), ["e0", "e1"], NOW)


def test_a_413_is_split_in_halves_even_when_it_names_an_event() -> None:
    """Too large is about the batch, not one event: halves, not the event alone."""
    events = list(range(8))
    assert split_refused(events, Refused(413, "too large", 1)) == [events[:4], events[4:]]
    assert split_refused(events, Refused(400, "bad", 1)) == [[0], [1], list(range(2, 8))]


def test_a_refusal_whose_body_is_not_utf8_is_kept_with_replacements() -> None:
    body = b"<html>\xff\xfe too large \xc3</html>"
    outcome = classify(Reply(413, {}, body), ["e0", "e1"], NOW)
    assert outcome == Refused(413, "<html>\ufffd\ufffd too large \ufffd</html>", None)
    assert kept_body(body, mask) == outcome.reason


def test_the_key_is_masked_in_every_string_of_lists_and_objects() -> None:
    document = {"errors": [f"Bearer {KEY}", {"echo": [KEY]}], KEY: [[KEY]]}
    assert masked(document, mask) == {"errors": ["Bearer ***", {"echo": ["***"]}], "***": [["***"]]}


def nested(levels: int, inner: object, kind: str) -> object:
    """``inner`` inside ``levels`` lists or objects."""
    value = inner
    for _ in range(levels):
        value = [value] if kind == "list" else {"a": value}
    return value


@pytest.mark.parametrize("kind", ["list", "object"])
def test_nesting_is_kept_to_max_depth_and_cut_below(kind: str) -> None:
    """Lists and objects at MAX_DEPTH levels are kept (their strings masked); one level
    deeper, the innermost becomes None."""
    assert masked(nested(MAX_DEPTH, KEY, kind), mask) == nested(MAX_DEPTH, "***", kind)
    deeper = nested(MAX_DEPTH + 1, KEY, kind)
    assert masked(deeper, mask) == nested(MAX_DEPTH, None, kind)


def test_escaped_key_beside_lone_surrogates_is_masked_and_stays_utf8() -> None:
    """A page (not JSON) echoing the key JSON-escaped is masked; the lone surrogates
    escaped beside it stay escaped: decoded they could not be stored as UTF-8."""
    escaped = KEY.replace("/", "\\u002f")
    text = f"<p>Bearer {escaped} \\ud800 \\udfff \\ud7ff \\ue000</p>"
    kept = masked_text(text, mask)
    assert kept == "<p>Bearer *** \\ud800 \\udfff \ud7ff \ue000</p>"
    kept.encode("utf-8")  # no lone surrogate


@pytest.mark.parametrize(
    "item",
    [
        {"event_id": [f"Bearer {KEY}"]},  # an event_id that is not text
        {"event_id": "e0", "index": f"Bearer {KEY}"},  # an index that is not one
    ],
)
def test_what_an_unaccounted_answer_quotes_of_a_bad_item_is_masked(item: dict) -> None:
    body = orjson.dumps({"accepted": 1, "duplicates": 0, "rejected": [item]})
    with pytest.raises(UnaccountedAnswerError) as raised:
        classify(Reply(200, {}, body, mask=mask), ["e0", "e1"], NOW)
    assert "Bearer ***" in str(raised.value)
    assert not any(form in str(raised.value) for form in leak_forms(KEY))
