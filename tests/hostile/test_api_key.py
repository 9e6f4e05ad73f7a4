"""The API key never shows: not in a one-line configuration error, a log, status, the
queue database, dead letters or the metrics — also when a server echoes it back."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from tests.hostile.servers import BadServer
from tests.processes import BridgeProcess, free_port, python_env, run_cli, status_json, wait_for

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
