"""PhyCloud as a hostile world serves it: real HTTP servers on 127.0.0.1 that trickle,
flood, tell the bridge to come back at once, or answer 200 with a captive portal."""

from __future__ import annotations

import email.utils
import signal
import time
from pathlib import Path

import pytest

from phytrace_edge.errors import TransientSendError, UnexpectedAnswerError
from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import MAX_REPLY_BYTES, HttpTransport
from tests.hostile.servers import BadServer, answer, elapsed, huge_body, trickle
from tests.processes import BridgeProcess, status_json, wait_for
from tests.queue_events import put_events

BODY = b'{"events":[{"event_id":"x"}]}'
HEADERS = {"Content-Type": "application/json"}


def test_a_trickling_server_is_cut_off_at_http_timeout_s() -> None:
    # one byte every 0.3 s: each read is quick, so per-read timeouts never fire
    with BadServer(trickle(0.3)) as server:
        transport = HttpTransport(server.endpoint, Secret("k" * 16), timeout_s=1.0)
        took, result = elapsed(lambda: transport.post_events(BODY, HEADERS))
        transport.close()
    assert isinstance(result, TransientSendError), result
    assert "HTTP_TIMEOUT_S" in str(result)
    assert took < 10  # a bound, not a speed: before the fix it lasted until the test died
    assert server.bytes_sent < 40


def test_a_huge_answer_is_not_read_into_memory() -> None:
    with BadServer(huge_body(4 * 1024**3)) as server:
        transport = HttpTransport(server.endpoint, Secret("k" * 16), timeout_s=5.0)
        _, reply = elapsed(lambda: transport.post_events(BODY, HEADERS))
        transport.close()
        wait_for(lambda: server.bytes_sent > 0, 5, "the server to send")
    assert not isinstance(reply, Exception), reply
    assert len(reply.body) <= MAX_REPLY_BYTES  # type: ignore[union-attr]
    assert server.bytes_sent < 64 * 1024**2  # it stopped reading: the kernel buffers, not 4 GB


@pytest.mark.parametrize(
    "retry_after",
    ["0", "-1", email.utils.formatdate(time.time() - 3600, usegmt=True)],
    ids=["zero", "negative", "past-date"],
)
def test_retry_after_never_makes_a_tight_loop(tmp_path: Path, retry_after: str) -> None:
    store = QueueStore.open(tmp_path / "q.db")
    store.put({"event_id": "a", "n": 1})
    policy = SendPolicy(retry_min_s=0.5, retry_max_s=2.0)
    with BadServer(answer("503 Service Unavailable", {"Retry-After": retry_after}, b"")) as server:
        sender = Sender(store, HttpTransport(server.endpoint, Secret(""), 5.0), policy)
        sender.drain(deadline=time.monotonic() + 3.0)
        sender.transport.close()
    # waits of at least RETRY_MIN_S: at most 3 s / 0.5 s + the first try (was ~800)
    assert 2 <= server.requests <= 8, server.requests
    assert store.counter("depth") == 1  # and nothing was dropped
    store.close()


def test_a_captive_portal_200_does_not_delete_the_batch(tmp_path: Path) -> None:
    store = QueueStore.open(tmp_path / "q.db")
    put_events(store, [{"event_id": f"e{i}"} for i in range(5)])
    portal = answer(
        "200 OK",
        {"Content-Type": "text/html"},
        b"<html><body>Welcome to Airport Wi-Fi. Please log in.</body></html>",
    )
    with BadServer(portal) as server:
        sender = Sender(store, HttpTransport(server.endpoint, Secret(""), 5.0), SendPolicy())
        with pytest.raises(UnexpectedAnswerError, match="captive portal"):
            _send_once(sender)
        sender.drain(deadline=time.monotonic() + 1.5)
        sender.transport.close()
    assert store.counter("depth") == 5 and store.stats().drops == {}
    assert sender.stats.unexpected_answers >= 2 and sender.stats.events_sent == 0
    assert "without PhyCloud's answer (text/html" in str(sender.stats.last_error)
    store.close()


def _send_once(sender: Sender) -> None:
    """One attempt of one batch, the classification raised rather than retried."""
    from phytrace_edge.ship.responses import classify
    from phytrace_edge.ship.transport import request_headers

    batch = sender.store.claim_batch(10, 10**6)
    assert batch is not None
    try:
        body = b'{"events":[' + b",".join(e.json for e in batch.events) + b"]}"
        reply = sender.transport.post_events(body, request_headers(batch.events, "none"))
        classify(reply, [event.event_id for event in batch.events], time.time())
    finally:
        sender.store.release(batch)


def test_a_200_that_does_not_account_for_the_batch_shows_in_status(tmp_path: Path) -> None:
    """A real bridge against PhyCloud answering `accepted: 0` to everything: nothing is
    deleted or dead-lettered, and `status --json` counts the answers."""
    none_accepted = answer(
        "200 OK",
        {"Content-Type": "application/json"},
        b'{"accepted": 0, "duplicates": 0, "rejected": []}',
    )
    with BadServer(none_accepted) as server:
        env = {
            "PHYCLOUD_ENDPOINT": server.endpoint,
            "QUEUE_PATH": str(tmp_path / "q.db"),
            "BRIDGE_INPUT": "sim",
            "SAMPLE_RATE_HZ": "20",
            "FLUSH_INTERVAL_S": "0.2",
            "RETRY_MIN_S": "0.05",
            "RETRY_MAX_S": "0.3",
        }
        bridge = BridgeProcess(tmp_path / "bridge.log", **env).start()
        try:
            # retried (and halved, or a single event retried every RETRY_MAX_S)
            doc = wait_for(
                lambda: (d := status_json(**env)[1]).get("unexpected_answers", 0) > 6 and d,
                60,
                "status to count the answers that do not add up",
            )
            bridge.signal(signal.SIGTERM)
            assert bridge.wait(30) == 0
        finally:
            bridge.stop()
    assert doc["sent_total"] == 0 and doc["dead_letters"] == 0 and doc["drops"] == {}
    assert doc["queue"]["depth"] > 0 and doc["accounting"]["balanced"]
    assert doc["last_error_class"] == "HTTP 200"
    assert doc["last_error"].startswith("PhyCloud's answer accounts for 0 of ")
    assert doc["last_error"].endswith(" - kept the batch")
    log = (tmp_path / "bridge.log").read_text()
    assert "WARNING phytrace_edge.ship.retries: PhyCloud's answer accounts for 0 of " in log
