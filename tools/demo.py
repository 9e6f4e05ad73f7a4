"""The main job, end to end on embedded defaults: a simulated delivery robot -> the
bridge (`phytrace-edge run`) -> the durable queue -> a local PhyCloud stub.

    python3 tools/demo.py                  # until Ctrl-C
    python3 tools/demo.py --duration 30    # stop by itself after 30 s

Creates and uses its own virtual environment (.venv-demo: the runtime and the stub,
no test tools) and keeps its files in .demo/. Open the printed page to watch the
telemetry arrive.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

from bootstrap import ROOT, ensure_venv  # tools/bootstrap.py, beside this file

STATE = ROOT / ".demo"
PREFERRED_PORT = 8000


def free_port(preferred: int) -> int:
    for port in (preferred, 0):
        with socket.socket() as sock:
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                continue
            return int(sock.getsockname()[1])
    raise RuntimeError("no free port on 127.0.0.1")


def get_json(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=5) as response:
        return json.loads(response.read())


def wait_until_up(url: str, stub: subprocess.Popen, deadline_s: float = 30) -> None:
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        if stub.poll() is not None:
            sys.exit(f"the stub exited; see {STATE / 'stub.log'}")
        try:
            get_json(f"{url}/healthz")
            return
        except OSError:
            time.sleep(0.1)
    sys.exit(f"the stub did not come up; see {STATE / 'stub.log'}")


def status(python: str, env: dict[str, str]) -> dict:
    result = subprocess.run(
        [python, "-m", "phytrace_edge", "status", "--json"],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=30,
    )
    return json.loads(result.stdout) if result.stdout else {}


def main() -> int:
    parser = argparse.ArgumentParser(description="phytrace-edge end to end, with a local stub")
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    parser.add_argument(
        "--port",
        type=int,
        default=PREFERRED_PORT,
        help="the stub's port (another is taken when it is busy; 0 = any)",
    )
    parser.add_argument(
        "--here",
        action="store_true",
        help="use this Python instead of .venv-demo (for the project's tests)",
    )
    args = parser.parse_args()
    # a shell that starts us in the background leaves SIGINT ignored, and Python then
    # installs no handler of its own: Ctrl-C (or a test's SIGINT) would do nothing
    signal.signal(signal.SIGINT, signal.default_int_handler)
    python = sys.executable if args.here else str(ensure_venv(".venv-demo", ".[stub]"))
    STATE.mkdir(exist_ok=True)
    port = free_port(args.port)
    url = f"http://127.0.0.1:{port}"
    env = {
        **os.environ,
        "PHYCLOUD_ENDPOINT": f"{url}/api/v1",
        "BRIDGE_INPUT": "sim",
        "QUEUE_PATH": str(STATE / "queue.db"),
        "SOURCE_ID": os.environ.get("SOURCE_ID", "demo-robot-001"),
        "FLUSH_INTERVAL_S": "1",
        # beyond the table: the motor's temperature when it changes, and health every 10 s
        "TOPICS_EXTRA": os.environ.get("TOPICS_EXTRA", "/motor/temperature mode=on_change"),
        "HEALTH_EVENT_INTERVAL_S": os.environ.get("HEALTH_EVENT_INTERVAL_S", "10"),
        "PYTHONUNBUFFERED": "1",
    }
    with (STATE / "stub.log").open("a") as stub_log, (STATE / "bridge.log").open("a") as log:
        stub = subprocess.Popen(
            [
                python,
                "-m",
                "phytrace_edge",
                "stub",
                "--port",
                str(port),
                "--db",
                str(STATE / "phycloud-stub.db"),
            ],
            stdout=stub_log,
            stderr=stub_log,
            cwd=ROOT,
            start_new_session=True,  # Ctrl-C reaches only the demo, which stops them in order
        )
        bridge = None
        try:
            wait_until_up(url, stub)
            # its own session too: a second signal would make it exit without flushing
            bridge = subprocess.Popen(
                [python, "-m", "phytrace_edge", "run"],
                stdout=log,
                stderr=log,
                env=env,
                cwd=ROOT,
                start_new_session=True,
            )
            print(f"PhyCloud stub: {url}/  (open it to watch the robot)")
            print(f"bridge: simulated robot -> queue {STATE / 'queue.db'} -> {url}/api/v1")
            print(f"logs: {STATE}/bridge.log, {STATE}/stub.log. Ctrl-C stops both.\n", flush=True)
            stop_at = None if args.duration is None else time.monotonic() + args.duration
            while stop_at is None or time.monotonic() < stop_at:
                time.sleep(2)
                if bridge.poll() is not None:
                    print(f"the bridge exited ({bridge.returncode}); see {STATE}/bridge.log")
                    return 1
                doc, stats = status(python, env), get_json(f"{url}/api/v1/stats")
                if doc:
                    health = "healthy" if doc["healthy"] else ", ".join(doc["problems"])
                    print(
                        f"  events built {doc['queued_total']:>5}  waiting "
                        f"{doc['queue']['depth']:>3}  delivered {doc['sent_total']:>5} "
                        f"({doc['send_rate_eps']:.1f}/s)  stub stored {stats['unique']:>5}  "
                        f"{health or 'starting'}",
                        flush=True,
                    )
        except KeyboardInterrupt:
            print()
        finally:
            if bridge is not None and bridge.poll() is None:
                bridge.send_signal(signal.SIGTERM)
                bridge.wait(timeout=30)
            final = get_json(f"{url}/api/v1/stats") if stub.poll() is None else {}
            stub.terminate()
            stub.wait(timeout=10)
    doc = status(python, env)
    if doc and final:
        print(
            f"stopped: {doc['queued_total']} events queued in total, {doc['sent_total']} "
            f"delivered, {doc['queue']['depth']} left in the queue; the stub holds "
            f"{final['unique']} unique events ({final['duplicates']} duplicates)"
        )
    return 0 if bridge is not None and bridge.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
