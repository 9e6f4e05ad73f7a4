"""``ingest/safe_text.py``: any str made encodable as UTF-8 (what orjson needs), with
lone surrogates replaced by U+FFFD and the caller told that something was."""

from __future__ import annotations

import json

import orjson
import pytest
from hypothesis import given
from hypothesis import strategies as st

from phytrace_edge.ingest.convert import checked_text, text
from phytrace_edge.ingest.safe_text import safe_bytes, safe_json, safe_str

FFFD = "\ufffd"


@pytest.mark.parametrize(
    ("broken", "repaired"),
    [
        ("\ud800", FFFD),  # a lone high surrogate
        ("\udfff", FFFD),  # a lone low surrogate
        ("order-\ud800-7", f"order-{FFFD}-7"),
        ("\udc00\ud800", FFFD * 2),  # low then high: no pair
        ("\ud800\ud800x", f"{FFFD}{FFFD}x"),
        ("caf\udce9", f"caf{FFFD}"),  # what surrogateescape makes of the byte 0xe9
        ("é\ud83d\ude00", "é😀"),  # a pair as two code points: the character it stands for
    ],
)
def test_lone_surrogates_become_the_replacement_character(broken: str, repaired: str) -> None:
    assert safe_str(broken) == (repaired, True)
    orjson.dumps(repaired)


@pytest.mark.parametrize("fine", ["", "odom", "Zürich", "温度", "😀 astral", "\ufffd", "a\x00b"])
def test_a_string_that_is_fine_comes_back_as_it_is(fine: str) -> None:
    repaired, changed = safe_str(fine)
    assert repaired is fine and changed is False


# hypothesis leaves surrogates out of its characters: they are added here
ANY_TEXT = st.text(alphabet=st.one_of(st.characters(), st.integers(0xD800, 0xDFFF).map(chr)))


@given(ANY_TEXT)
def test_any_string_is_encodable_after_and_unchanged_if_it_was(value: str) -> None:
    repaired, changed = safe_str(value)
    orjson.dumps(repaired)
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        assert changed
    else:
        assert (repaired, changed) == (value, False)


def test_bytes_that_are_not_utf8_are_replaced() -> None:
    assert safe_bytes(b"lidar") == ("lidar", False)
    assert safe_bytes("Zürich".encode()) == ("Zürich", False)
    assert safe_bytes(b"s\xff\xfe4") == (f"s{FFFD}{FFFD}4", True)
    assert safe_bytes(b"\xed\xa0\x80") == (FFFD * 3, True)  # an encoded surrogate


def test_json_keys_and_nested_values_are_repaired_in_place() -> None:
    document = json.loads(
        '{"\\ud800": 1, "ok": ["a", "\\udfff", {"deep": "\\ud83d\\ude00",'
        ' "x\\udc00": ["\\ud801"]}], "n": 3.5, "t": true, "z": null}'
    )
    repaired, count = safe_json(document)
    assert repaired is document
    assert count == 4  # two keys, two values; the escaped pair is a character already
    assert repaired == {
        FFFD: 1,
        "ok": ["a", FFFD, {"deep": "😀", f"x{FFFD}": [FFFD]}],
        "n": 3.5,
        "t": True,
        "z": None,
    }
    assert list(repaired) == [FFFD, "ok", "n", "t", "z"]  # the keys' order is kept
    orjson.dumps(repaired)


def test_json_that_is_fine_is_not_touched() -> None:
    document = {"order_id": "o-1", "stops": ["Zürich", {"温度": [1, 2]}]}
    assert safe_json(document) == (document, 0)
    assert safe_json("\ud800") == (FFFD, 1)
    assert safe_json(7) == (7, 0)


def test_a_document_as_deep_as_the_parser_allows_costs_no_stack() -> None:
    document = json.loads("[" * 900 + '"\\ud800"' + "]" * 900)
    repaired, count = safe_json(document)
    assert count == 1
    for _ in range(900):
        (repaired,) = repaired
    assert repaired == FFFD


def test_text_fields_are_cut_then_repaired() -> None:
    assert checked_text("a" * 300) == ("a" * 256, False)
    assert checked_text("x\ud800") == (f"x{FFFD}", True)
    assert checked_text(b"s\xff") == (f"s{FFFD}", True)
    assert checked_text(5) == (None, False)
    assert checked_text("é" * 3000, 2048) == ("é" * 2048, False)
    assert text("frame\udcff") == f"frame{FFFD}"
