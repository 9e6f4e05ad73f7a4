"""A fleet recovers politely: 20 bridges wait out an outage of one PhyCloud, and when
it comes back their first successful sends spread over the backoff jitter window
instead of landing in the same instant."""

from __future__ import annotations

import threading
import time
from collections import Counter
from pathlib import Path

from phytrace_edge import run_simulation
from phytrace_edge.queue.options import QueueLimits
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import HttpTransport
from phytrace_edge.udm.event import new_event_id
from phytrace_edge.units import MIB
from tests.processes import wait_for
from tests.queue_events import put_events

ROBOTS = 20
RETRY_MAX_S = 2.0


def robot_events(template: list[dict], robot: int) -> list[dict]:
    source = f"robot-{robot:02d}"
    return [
        {
            **event,
            "event_id": new_event_id(),
            "source_id": source,
            "identity": {**event["identity"], "source_id": source},
        }
        for event in template
    ]


def test_twenty_bridges_resume_spread_over_the_jitter_window(tmp_path: Path, stub) -> None:
    template: list[dict] = []
    run_simulation(20, sink=template.append)
    stub.set_faults(fixed_status=503)  # PhyCloud is down
    stores, senders, threads = [], [], []
    for robot in range(ROBOTS):
        store = QueueStore.open(tmp_path / f"q{robot}.db", limits=QueueLimits(max_bytes=64 * MIB))
        put_events(store, robot_events(template, robot))
        sender = Sender(
            store,
            HttpTransport(stub.endpoint, Secret(""), timeout_s=5),
            SendPolicy(batch_size=50, retry_min_s=0.2, retry_max_s=RETRY_MAX_S),
        )
        stores.append(store)
        senders.append(sender)
        threads.append(
            threading.Thread(target=sender.drain, kwargs={"deadline": time.monotonic() + 90})
        )
    try:
        for thread in threads:
            thread.start()
        # by the 4th retry every robot's backoff window has reached RETRY_MAX_S
        wait_for(lambda: all(s.stats.retries >= 4 for s in senders), 60, "the fleet to back off")
        recovered_at = time.time()
        stub.set_faults(fixed_status=None)
        for thread in threads:
            thread.join(timeout=60)
    finally:
        for sender in senders:
            sender.stop.set()
        for store in stores:
            store.close()

    assert stub.stats()["unique"] == ROBOTS * len(template)
    firsts = sorted(sender.stats.last_success_at - recovered_at for sender in senders)
    span = firsts[-1] - firsts[0]
    per_100ms = Counter(int(t / 0.1) for t in firsts)
    print(f"\nfirst successes after recovery: {[round(t, 2) for t in firsts]}")
    assert all(0 <= t <= RETRY_MAX_S * 1.5 for t in firsts)
    assert span >= 0.4 * RETRY_MAX_S, f"resumed within {span:.2f} s: a thundering herd"
    assert max(per_100ms.values()) <= ROBOTS // 3, f"too many in one 100 ms slot: {per_100ms}"
