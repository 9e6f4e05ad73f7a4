"""What PhyCloud's answer means (ship/responses.py), on known answers: the accounting
that must hold before anything is deleted, and the key masked in PhyCloud's words only
after they are decoded."""

from __future__ import annotations

import orjson
import pytest

from phytrace_edge.errors import UnaccountedAnswerError, UnexpectedAnswerError
from phytrace_edge.redact import leak_forms, redact
from phytrace_edge.ship.responses import (
    Accepted,
    Refused,
    Reply,
    Unaccounted,
    account,
    classify,
    kept_body,
    masked_text,
)

IDS = ["e0", "e1", "e2", "e3"]
NOW = 1_800_000_000.0


def answer(accepted: int, duplicates: int | None = 0, rejected: list | None = None) -> dict:
    document: dict = {"accepted": accepted, "rejected": rejected or []}
    if duplicates is not None:
        document["duplicates"] = duplicates
    return document


# ------------------------------------------------------------------ the accounting


@pytest.mark.parametrize(
    ("document", "rejected"),
    [
        (answer(4), {}),
        (answer(1, 3), {}),  # a resend: most of it was stored before
        (answer(4, duplicates=None), {}),  # duplicates absent: 0
        (answer(3, rejected=[{"index": 2, "event_id": "e2", "reason": "bad"}]), {2: "bad"}),
        (answer(3, rejected=[{"event_id": "e1", "reason": "bad"}]), {1: "bad"}),  # no index
        (answer(3, rejected=[{"index": 0, "event_id": "e0"}]), {0: "rejected"}),  # no reason
        (
            answer(
                1,
                1,
                [
                    {"index": 3, "event_id": "e3", "reason": "x"},
                    {"index": 0, "event_id": "e0", "reason": "y"},
                ],
            ),
            {0: "y", 3: "x"},
        ),
    ],
)
def test_an_answer_that_accounts_for_every_event(document: dict, rejected: dict) -> None:
    assert account(document, IDS) == rejected


@pytest.mark.parametrize(
    ("document", "problem"),
    [
        (
            answer(0),
            "PhyCloud's answer accounts for 0 of 4 events (accepted 0, duplicates 0, rejected 0)",
        ),
        (
            answer(4, 1),
            "PhyCloud's answer accounts for 5 of 4 events (accepted 4, duplicates 1, rejected 0)",
        ),
        (answer(4, "0"), "PhyCloud's answer has duplicates '0', not a count"),
        (answer(4, -1), "PhyCloud's answer has duplicates -1, not a count"),
        (answer(3, rejected=["e1"]), "PhyCloud's answer's rejected[0] is not an object"),
        (  # an index alone does not say which event: a 1-based one names the next
            answer(3, rejected=[{"index": 1, "reason": "bad"}]),
            "PhyCloud's answer's rejected[0] gives index 1 with no event_id: not the event there",
        ),
        (  # 1-based: index 1 for the first event
            answer(3, rejected=[{"index": 1, "event_id": "e0"}]),
            "PhyCloud's answer's rejected[0] gives index 1 with event_id 'e0': not the event there",
        ),
        (
            answer(3, rejected=[{"index": 4, "event_id": "e3"}]),
            "PhyCloud's answer's rejected[0] has index 4, not one of 0..3",
        ),
        (
            answer(3, rejected=[{"index": True, "event_id": "e1"}]),
            "PhyCloud's answer's rejected[0] has index True, not one of 0..3",
        ),
        (
            answer(3, rejected=[{"event_id": "e9"}]),
            "PhyCloud's answer's rejected[0] names event_id 'e9', not an event of the batch",
        ),
        (
            answer(3, rejected=[{"event_id": 7}]),
            "PhyCloud's answer's rejected[0] has event_id 7, not text",
        ),
        (
            answer(3, rejected=[{"reason": "bad"}]),
            "PhyCloud's answer's rejected[0] names no event (neither event_id nor index)",
        ),
        (
            answer(2, rejected=[{"event_id": "e1"}, {"index": 1, "event_id": "e1"}]),
            "PhyCloud's answer's rejected[1] rejects event_id 'e1' a second time",
        ),
    ],
)
def test_an_answer_that_does_not_add_up_is_not_trusted(document: dict, problem: str) -> None:
    with pytest.raises(Unaccounted) as raised:
        account(document, IDS)
    assert str(raised.value) == problem


def test_an_event_without_an_event_id_is_named_by_its_index_alone() -> None:
    ids = ["e0", "", "e2"]
    assert account(answer(2, rejected=[{"index": 1, "event_id": None}]), ids) == {1: "rejected"}
    with pytest.raises(Unaccounted, match="names no event"):  # which of them? not said
        account(answer(2, rejected=[{"event_id": None}]), ids)


def test_an_event_id_twice_in_the_batch_may_be_rejected_twice() -> None:
    ids = ["e0", "e0", "e1"]
    rejected = [{"event_id": "e0", "reason": "a"}, {"event_id": "e0", "reason": "b"}]
    assert account(answer(1, rejected=rejected), ids) == {0: "a", 1: "b"}
    with pytest.raises(Unaccounted, match="a second time"):
        account(answer(0, rejected=[*rejected, {"event_id": "e0"}]), ids)


def test_classify_keeps_a_batch_whose_answer_does_not_add_up() -> None:
    reply = Reply(200, {}, orjson.dumps(answer(0)))
    with pytest.raises(UnaccountedAnswerError) as raised:
        classify(reply, IDS, NOW)
    assert str(raised.value) == (
        "PhyCloud's answer accounts for 0 of 4 events (accepted 0, duplicates 0, rejected 0)"
        " - kept the batch"
    )
    assert raised.value.status == 200
    assert isinstance(raised.value, UnexpectedAnswerError)  # counted as unexpected answers


def test_classify_accepts_an_answer_that_adds_up() -> None:
    body = orjson.dumps(answer(3, rejected=[{"index": 1, "event_id": "e1", "reason": "why"}]))
    assert classify(Reply(200, {}, body), IDS, NOW) == Accepted({1: "why"})


# ------------------------------------------------------------------ masking after decoding

KEY = "phk_live/Zq8v2+K9x7/Lw3"
MASK = lambda text: redact(text, leak_forms(KEY))  # noqa: E731 - as the transport makes it
ESCAPED = {
    "slash": KEY.replace("/", "\\/"),
    "u002f": KEY.replace("/", "\\u002f"),
    "u002F": KEY.replace("/", "\\u002F"),
    "every-char": "".join(f"\\u{ord(c):04x}" for c in KEY),
}


def raw_answer(reasons: list[str]) -> bytes:
    """A 200 whose rejected reasons are written into the JSON as given (escapes kept)."""
    ids = [f"e{i}" for i in range(len(reasons))]
    items = ",".join(
        f'{{"index":{i},"event_id":"{ids[i]}","reason":"{reason}"}}'
        for i, reason in enumerate(reasons)
    )
    return f'{{"accepted":0,"duplicates":0,"rejected":[{items}]}}'.encode()


def key_forms_in(text: str) -> list[str]:
    """The forms of KEY ``text`` still shows, decoded or escaped."""
    forms = {KEY, *leak_forms(KEY), *ESCAPED.values(), KEY.split("/")[1]}
    return [form for form in forms if form in text]


def test_rejected_reasons_are_masked_after_they_are_decoded() -> None:
    reasons = [f"bad; you sent Authorization: Bearer {form}" for form in ESCAPED.values()]
    body = raw_answer(reasons)
    ids = [f"e{i}" for i in range(len(reasons))]
    outcome = classify(Reply(200, {}, body, mask=MASK), ids, NOW)
    assert outcome == Accepted(dict.fromkeys(range(4), "bad; you sent Authorization: Bearer ***"))
    # the mask of the raw bytes (what the transport did alone) misses every escaped form
    assert MASK(body.decode()) == body.decode()
    unmasked = classify(Reply(200, {}, body), ids, NOW)
    assert isinstance(unmasked, Accepted)
    assert all(reason.endswith(KEY) for reason in unmasked.rejected.values())


@pytest.mark.parametrize("form", ESCAPED.values(), ids=ESCAPED.keys())
def test_a_refusals_body_is_masked_after_it_is_decoded(form: str) -> None:
    body = f'{{"error":"bad event; Authorization: Bearer {form}","index":0}}'.encode()
    outcome = classify(Reply(400, {}, body, mask=MASK), ["e0", "e1"], NOW)
    assert outcome == Refused(400, '{"error":"bad event; Authorization: Bearer ***","index":0}', 0)


@pytest.mark.parametrize("form", ESCAPED.values(), ids=ESCAPED.keys())
def test_a_body_that_is_not_json_is_masked_with_its_escapes_decoded(form: str) -> None:
    html = f"<html><p>Bearer {form}</p></html>"
    assert masked_text(html, MASK) == "<html><p>Bearer ***</p></html>"
    cut = f'{{"error":"Bearer {form} and more'  # an answer cut at 64 KiB: not JSON
    outcome = classify(Reply(413, {}, cut.encode(), mask=MASK), ["e0"], NOW)
    assert isinstance(outcome, Refused) and key_forms_in(outcome.reason) == []
    assert outcome.reason == '{"error":"Bearer *** and more'


@pytest.mark.parametrize("status", [400, 422])
def test_a_gateways_html_refusal_blames_no_event(status: int) -> None:
    """nginx requiring a client certificate answers 400 with a page: splitting the
    batch on it would dead-letter every event, one by one."""
    page = b"<html><h1>400 No required SSL certificate was sent</h1></html>"
    reply = Reply(status, {"content-type": "text/html"}, page)
    with pytest.raises(UnexpectedAnswerError, match=f"HTTP {status} without PhyCloud's answer"):
        classify(reply, ["e0", "e1"], NOW)
    assert isinstance(classify(Reply(413, {}, page), ["e0", "e1"], NOW), Refused)


def test_text_without_the_key_keeps_its_escapes() -> None:
    text = r"C:\new\table \u00e9 \/ plain"
    assert masked_text(text, MASK) == text


def test_the_key_is_masked_before_a_reason_is_cut() -> None:
    reason = "x" * 505 + ESCAPED["every-char"]  # the cut at 512 would keep "phk_liv"
    body = raw_answer([reason])
    outcome = classify(Reply(200, {}, body, mask=MASK), ["e0"], NOW)
    assert outcome == Accepted({0: "x" * 505 + "***"})


def test_what_an_unaccounted_answer_quotes_is_masked() -> None:
    body = orjson.dumps(answer(3, rejected=[{"event_id": f"Bearer {KEY}"}]))
    with pytest.raises(UnaccountedAnswerError) as raised:
        classify(Reply(200, {}, body, mask=MASK), IDS, NOW)
    assert "names event_id 'Bearer ***', not an event of the batch" in str(raised.value)
    assert key_forms_in(str(raised.value)) == []


def test_a_deeply_nested_body_is_kept_without_its_depths() -> None:
    deep = "[" * 1020 + "]" * 1020  # within orjson's limit (1024), past Python's (1000)
    body = f'{{"error":"Bearer {ESCAPED["slash"]}","detail":{deep}}}'.encode()
    kept = kept_body(body, MASK)
    assert kept.startswith('{"error":"Bearer ***","detail":[[[')
    assert "null" in kept and key_forms_in(kept) == []
