"""Real processes for integration and chaos tests: the stub and the bridge.

Every process binds to 127.0.0.1, is found by its pid and is killed at teardown.
Waiting is always on a condition with a deadline, never a bare sleep.
"""

from __future__ import annotations

import json
import os
import random
import re
import signal
import socket
import ssl
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parent.parent


def wait_for(condition: Callable[[], Any], timeout: float, what: str, every: float = 0.05) -> Any:
    """Poll ``condition`` until it returns something truthy; fail after ``timeout``."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(every)


def free_port() -> int:
    """A free port on 127.0.0.1 *below* the ephemeral range (32768 and up on Linux). A
    client that keeps connecting to a port nobody listens on yet (a bridge retrying
    while the stub is down) can be given that same port as its own source port, and
    then connects to itself; a server port outside the ephemeral range rules that out."""
    rng = random.Random()
    for _ in range(200):
        port = rng.randrange(20000, 32000)
        with socket.socket() as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise AssertionError("no free port on 127.0.0.1 between 20000 and 32000")


def python_env(**extra: str) -> dict[str, str]:
    """The test process's environment without the bridge's settings or a proxy of the
    machine (tests talk to 127.0.0.1 only), plus ``extra``."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("PHYCLOUD_", "QUEUE_")) and not k.lower().endswith("_proxy")
    }
    env.update(PYTHONPATH=str(ROOT), PYTHONUNBUFFERED="1", **extra)
    return env


def run_cli(*args: str, timeout: float = 120, **env: str) -> subprocess.CompletedProcess[str]:
    """``phytrace-edge ARGS`` in a fresh process, its settings from ``env``."""
    return subprocess.run(
        [sys.executable, "-m", "phytrace_edge", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=python_env(**env),
    )


def status_json(**env: str) -> tuple[int, dict[str, Any]]:
    """``phytrace-edge status --json``: (exit code, document or {})."""
    result = run_cli("status", "--json", timeout=30, **env)
    return result.returncode, json.loads(result.stdout) if result.stdout else {}


class StubProcess:
    """``phytrace-edge stub`` on a free loopback port, restartable on the same port."""

    def __init__(self, db: Path, *args: str, client: tuple[Path, Path] | None = None) -> None:
        """``args`` for ``phytrace-edge stub``; ``client``: the certificate and key the
        test itself presents to a stub that requires one (``--tls-client-ca``)."""
        self.db, self.args = db, args
        self.verify = _test_client_context(client) if "--tls-cert" in args else True
        self.port = free_port()
        self.scheme = "https" if "--tls-cert" in args else "http"
        self.process: subprocess.Popen[str] | None = None
        self.log = db.with_suffix(".log")

    @property
    def url(self) -> str:
        return f"{self.scheme}://127.0.0.1:{self.port}"

    @property
    def endpoint(self) -> str:
        return f"{self.url}/api/v1"

    def start(self) -> StubProcess:
        command = [
            sys.executable,
            "-m",
            "phytrace_edge",
            "stub",
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
            "--db",
            str(self.db),
            *self.args,
        ]
        with self.log.open("a") as log:
            self.process = subprocess.Popen(
                command, stdout=subprocess.PIPE, stderr=log, text=True, env=python_env()
            )
        line = self.process.stdout.readline()  # type: ignore[union-attr]
        match = re.search(r"127\.0\.0\.1:(\d+)", line)
        if not match:
            self.stop()
            raise AssertionError(f"stub did not start: {line!r}; see {self.log}")
        self.port = int(match.group(1))
        try:
            wait_for(self._healthy, 20, "the stub to answer /healthz")
        except AssertionError:
            self.stop()  # never left running when it did not come up
            raise
        return self

    def _healthy(self) -> bool:
        try:
            return (
                httpx.get(f"{self.url}/healthz", timeout=1, verify=self.verify).status_code == 200
            )
        except httpx.HTTPError:
            return False

    def kill(self) -> None:
        """SIGKILL: no chance to finish anything."""
        if self.process and self.process.poll() is None:
            os.kill(self.process.pid, signal.SIGKILL)
            self.process.wait(timeout=10)

    def stop(self) -> None:
        if self.process and self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=3)  # uvicorn waits for requests still in flight
            except subprocess.TimeoutExpired:
                self.kill()

    def stats(self) -> dict[str, Any]:
        return httpx.get(f"{self.endpoint}/stats", timeout=5, verify=self.verify).json()

    def events(self) -> list[dict[str, Any]]:
        """Every event the stub stored, in the order it stored them."""
        events: list[dict[str, Any]] = []
        after = 0
        while True:
            page = httpx.get(
                f"{self.endpoint}/events",
                params={"after": after, "limit": 10000},
                timeout=30,
                verify=self.verify,
            ).json()
            events += page["events"]
            if not page["events"]:
                return events
            after = page["next_after"]

    def event_ids(self) -> list[str]:
        return [event["event_id"] for event in self.events()]

    def set_faults(self, **faults: Any) -> dict[str, Any]:
        return httpx.put(
            f"{self.endpoint}/faults", json=faults, timeout=5, verify=self.verify
        ).json()


def _test_client_context(client: tuple[Path, Path] | None) -> ssl.SSLContext:
    """How the test talks to a TLS stub: no verification of the stub (the bridge's
    verification is what is tested), its own client certificate when one is needed."""
    context = ssl.create_default_context()
    context.check_hostname = False
    context.verify_mode = ssl.CERT_NONE
    if client is not None:
        context.load_cert_chain(*client)
    return context


class BridgeProcess:
    """``phytrace-edge run`` with settings from the environment."""

    def __init__(
        self,
        log: Path,
        *,
        preexec: Callable[[], None] | None = None,
        command: list[str] | None = None,
        **env: str,
    ) -> None:
        """``preexec`` runs in the child before exec (a namespace to enter); ``command``
        replaces ``python -m phytrace_edge run`` (a wrapper that ends in it)."""
        self.env, self.log, self.preexec = env, log, preexec
        self.command = command or [sys.executable, "-m", "phytrace_edge", "run"]
        self.process: subprocess.Popen[bytes] | None = None

    def start(self) -> BridgeProcess:
        with self.log.open("a") as log:
            self.process = subprocess.Popen(
                self.command,
                stdout=log,
                stderr=log,
                env=python_env(**self.env),
                preexec_fn=self.preexec,
            )
        return self

    def signal(self, signum: int) -> None:
        if self.process and self.process.poll() is None:
            os.kill(self.process.pid, signum)

    def wait(self, timeout: float) -> int:
        assert self.process is not None
        return self.process.wait(timeout=timeout)

    def stop(self) -> None:
        if self.process and self.process.poll() is None:
            self.process.kill()
            self.process.wait(timeout=10)
