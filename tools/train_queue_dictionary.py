"""Train the zstd dictionary the queue compresses events with, from simulated events.

    .venv/bin/python tools/train_queue_dictionary.py

Writes phytrace_edge/queue/encoding/udm-events.zdict. Real robots' events share the UDM's keys
and structure, which is most of what a dictionary captures. Rows record the id of the
dictionary they were written with and the database keeps every dictionary it used,
so retraining never makes old rows unreadable.
"""

from __future__ import annotations

from pathlib import Path

import orjson
import zstandard

from phytrace_edge import run_simulation

DICTIONARY_BYTES = 16 * 1024
OUT = (
    Path(__file__).resolve().parent.parent
    / "phytrace_edge"
    / "queue"
    / "encoding"
    / "udm-events.zdict"
)


def main() -> None:
    samples: list[bytes] = []
    for seed in range(4):
        run_simulation(1500, seed=seed, sink=lambda event: samples.append(orjson.dumps(event)))
    dictionary = zstandard.train_dictionary(DICTIONARY_BYTES, samples)
    OUT.write_bytes(dictionary.as_bytes())
    print(f"{OUT}: {len(samples)} samples, dict_id {dictionary.dict_id()}")


if __name__ == "__main__":
    main()
