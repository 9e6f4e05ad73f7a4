"""The dds input's take loop (``take_each``) with a reader that does what cyclonedds-python
does when a sample cannot be decoded (measured on real Cyclone DDS: see ``take_each``;
the real thing: tests/integration/test_dds_text.py). No cyclonedds needed."""

from __future__ import annotations

import pytest

from phytrace_edge.ingest.sources.dds import take_each


class Undecodable(Exception):
    pass


class FakeReader:
    """A reader that does what cyclonedds-python 11 does: ``take(N=k)`` removes up to k
    samples from the cache, then decodes them, and raises if one cannot be decoded (all
    k are then lost); a failure of the C take (``dds_error``) removes nothing."""

    def __init__(self, samples: list[str], fail_c_take: bool = False) -> None:
        self.cache, self.fail_c_take, self.takes = list(samples), fail_c_take, 0

    def take(self, N: int = 1) -> list[str]:  # noqa: N803 - cyclonedds' name
        self.takes += 1
        if self.fail_c_take:
            raise DdsError("DDS_RETCODE_ALREADY_DELETED")
        taken, self.cache = self.cache[:N], self.cache[N:]
        if "bad" in taken:
            raise Undecodable("'utf-8' codec can't decode byte 0xff")
        return taken


class DdsError(Exception):
    pass


def take_all(reader: FakeReader, limit: int = 100) -> tuple[list[str], list[str]]:
    delivered: list[str] = []
    undecodable: list[str] = []
    take_each(reader, limit, delivered.append, lambda exc: undecodable.append(str(exc)), DdsError)
    return delivered, undecodable


def test_the_fake_reader_loses_a_whole_batch_as_cyclonedds_does() -> None:
    reader = FakeReader(["g1", "bad", "g2"])
    with pytest.raises(Undecodable):
        reader.take(N=100)
    assert reader.take(N=100) == []


def test_one_undecodable_sample_costs_only_itself() -> None:
    reader = FakeReader(["g1", "g2", "bad", "g3", "bad", "g4"])
    delivered, undecodable = take_all(reader)
    assert delivered == ["g1", "g2", "g3", "g4"]
    assert undecodable == ["'utf-8' codec can't decode byte 0xff"] * 2
    assert reader.takes == 7  # one a sample, and the one that found the cache empty


def test_a_take_round_is_bounded() -> None:
    reader = FakeReader(["bad"] * 5 + ["g1"])
    delivered, undecodable = take_all(reader, limit=3)
    assert (delivered, len(undecodable), reader.cache) == ([], 3, ["bad", "bad", "g1"])
    assert take_all(reader, limit=3) == (["g1"], ["'utf-8' codec can't decode byte 0xff"] * 2)


def test_a_failing_c_take_is_not_counted_as_undecodable() -> None:
    reader = FakeReader(["g1"], fail_c_take=True)
    with pytest.raises(DdsError):
        take_all(reader)
    assert reader.takes == 1
