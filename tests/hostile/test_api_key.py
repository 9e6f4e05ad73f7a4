"""The API key never shows: not in a one-line configuration error, a log, status, the
queue database, dead letters or the metrics — also when a server echoes it back."""

from __future__ import annotations

import gzip
import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from phytrace_edge.queue.store import QueueStore
from phytrace_edge.redact import Secret, leak_forms
from phytrace_edge.ship.options import SendPolicy
from phytrace_edge.ship.sender import Sender
from phytrace_edge.ship.transport import HttpTransport
from tests.hostile.servers import BadServer
from tests.processes import BridgeProcess, free_port, python_env, run_cli, status_json, wait_for
from tests.queue_events import put_events

KEY = "phk_live_Zq8v2K9x7Lw3"


@pytest.mark.parametrize(
    "key",
    ["Kq7zW\r\nXv9pT", "Kq7zW\nXv9pT", "Kq7zW Xv9pT", "Kq7zWé-Xv9pT", "Kq7zW\tXv9pT"],
    ids=["crlf", "lf", "space", "non-ascii", "tab"],
)
def test_a_malformed_key_is_one_line_that_does_not_show_it(tmp_path: Path, key: str) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "phytrace_edge", "run", "--input", "sim"],
        capture_output=True,
        text=True,
        timeout=60,
        env=python_env(PHYCLOUD_API_KEY=key, QUEUE_PATH=str(tmp_path / "q.db")),
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert lines[0].startswith("phytrace-edge: error: PHYCLOUD_API_KEY='***': must be printable")
    assert "Kq7zW" not in result.stderr + result.stdout and "Xv9pT" not in result.stderr


def echo_headers_as_400(connection: socket.socket, server: BadServer) -> None:
    """A server that quotes the request's Authorization header back in a 400: the
    rejection's text goes into a dead letter."""
    body = json.dumps({"error": f"bad event; you sent Authorization: Bearer {KEY}", "index": 0})
    raw = body.encode()
    server.send(
        connection,
        b"HTTP/1.1 400 Bad Request\r\nContent-Type: application/json\r\n"
        + f"X-Echo: Bearer {KEY}\r\nContent-Length: {len(raw)}\r\n\r\n".encode()
        + raw,
    )


def test_the_key_is_in_no_output_even_when_the_server_echoes_it(tmp_path: Path) -> None:
    queue = tmp_path / "q.db"
    metrics_port = free_port()
    with BadServer(echo_headers_as_400) as server:
        env = {
            "PHYCLOUD_ENDPOINT": server.endpoint,
            "PHYCLOUD_API_KEY": KEY,
            "QUEUE_PATH": str(queue),
            "BRIDGE_INPUT": "sim",
            "BATCH_SIZE": "1",
            "FLUSH_INTERVAL_S": "0.2",
            "METRICS_PORT": str(metrics_port),
            "LOG_LEVEL": "debug",
        }
        bridge = BridgeProcess(tmp_path / "bridge.log", **env).start()
        try:
            wait_for(lambda: dead_letters(env) >= 3, 60, "rejected events as dead letters")
            metrics = httpx.get(f"http://127.0.0.1:{metrics_port}/metrics", timeout=5).text
            status = cli(env, "status", "--json").stdout
            listing = cli(env, "dead-letters", "list").stdout
            exported = cli(env, "dead-letters", "export").stdout
            config = cli(env, "config", "--json").stdout
            bridge.signal(signal.SIGTERM)
            assert bridge.wait(30) == 0
        finally:
            bridge.stop()
    files = b"".join(p.read_bytes() for p in tmp_path.rglob("*") if p.is_file())
    outputs = metrics + status + listing + exported + config
    assert "***" in exported  # PhyCloud's words were kept, the key in them masked
    assert KEY not in outputs
    assert KEY.encode() not in files  # the log, the queue, its WAL, the dead letters


def dead_letters(env: dict[str, str]) -> int:
    return status_json(**env)[1].get("dead_letters", 0)


def cli(env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    return run_cli(*args, **env)


SLASHED_KEY = "phk_live/Zq8v2K9x7/Lw3Tn"
# how a JSON encoder may write the key: every one decodes to SLASHED_KEY
ESCAPED_KEYS = [
    SLASHED_KEY.replace("/", "\\/"),
    SLASHED_KEY.replace("/", "\\u002f"),
    SLASHED_KEY.replace("/", "\\u002F"),
    "".join(f"\\u{ord(c):04x}" for c in SLASHED_KEY),
]


def echo_escaped_key_in_rejections(connection: socket.socket, server: BadServer) -> None:
    """PhyCloud that rejects the first events of each batch, quoting the request's
    Authorization header in the reasons with the key JSON-escaped (one way per event);
    its answer accounts for every event, so the rejected ones become dead letters."""
    request = server.request
    body = request.body
    if request.headers.get("content-encoding") == "gzip":
        body = gzip.decompress(body)
    ids = [event["event_id"] for event in json.loads(body)["events"]]
    items = [
        f'{{"index":{i},"event_id":"{ids[i]}","reason":"unknown robot; Bearer {escaped}"}}'
        for i, escaped in enumerate(ESCAPED_KEYS[: len(ids)])
    ]
    answer = (
        f'{{"accepted":{len(ids) - len(items)},"duplicates":0,"rejected":[{",".join(items)}]}}'
    ).encode()
    server.send(
        connection,
        b"HTTP/1.1 200 OK\r\nContent-Type: application/json\r\n"
        + f"Content-Length: {len(answer)}\r\n\r\n".encode()
        + answer,
    )


def key_pieces_in(data: bytes) -> list[str]:
    """Every form of SLASHED_KEY found in ``data``: whole (as is, escaped,
    percent-encoded) or any piece of it between its slashes."""
    forms = {*leak_forms(SLASHED_KEY), *ESCAPED_KEYS, *SLASHED_KEY.split("/")}
    return sorted(form for form in forms if form.encode() in data)


def queue_files(queue: Path) -> bytes:
    """The queue's files as they are on disk: the database and its WAL."""
    return b"".join(
        path.read_bytes() for path in (queue, queue.with_name(queue.name + "-wal")) if path.exists()
    )


def test_a_key_echoed_with_json_escapes_is_masked_once_decoded(tmp_path: Path) -> None:
    queue = tmp_path / "q.db"
    store = QueueStore.open(queue)
    put_events(store, [{"event_id": f"e{i}", "n": i} for i in range(10)])
    with BadServer(echo_escaped_key_in_rejections) as server:
        transport = HttpTransport(server.endpoint, Secret(SLASHED_KEY), 5.0)
        sender = Sender(store, transport, SendPolicy(batch_size=10))
        try:
            assert sender.drain(deadline=time.monotonic() + 30) is True
        finally:
            transport.close()
    letters = store.dead_letters.list()
    assert [letter.event_id for letter in letters] == ["e0", "e1", "e2", "e3"]
    assert {letter.reason for letter in letters} == {"rejected: unknown robot; Bearer ***"}
    on_disk = queue_files(queue)  # the WAL holds the dead letters until a checkpoint
    store.close()
    on_disk += queue_files(queue)

    listing = run_cli("dead-letters", "list", QUEUE_PATH=str(queue))
    exported = run_cli("dead-letters", "export", QUEUE_PATH=str(queue))
    assert listing.returncode == 0 and exported.returncode == 0, listing.stderr + exported.stderr
    assert "4 dead letter(s)" in listing.stdout and "Bearer ***" in listing.stdout
    assert exported.stdout.count("unknown robot; Bearer ***") == 8  # reason and response
    outputs = (listing.stdout + listing.stderr + exported.stdout + exported.stderr).encode()
    assert key_pieces_in(on_disk) == [] and key_pieces_in(outputs) == []
