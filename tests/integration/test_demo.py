"""The README's main-job command runs end to end and stops cleanly."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[2]


def test_demo_runs_the_robot_through_the_bridge_to_the_stub() -> None:
    result = subprocess.run(
        [sys.executable, "tools/demo.py", "--here", "--port", "0", "--duration", "6"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert re.search(r"PhyCloud stub: http://127\.0\.0\.1:\d+/", result.stdout)
    assert "healthy" in result.stdout
    final = re.search(
        r"stopped: (\d+) events queued in total, (\d+) delivered, 0 left in the "
        r"queue; the stub holds (\d+) unique events",
        result.stdout,
    )
    assert final, result.stdout
    queued, delivered, stored = (int(n) for n in final.groups())
    assert queued > 0 and queued == delivered <= stored


def test_ctrl_c_stops_the_demo_cleanly() -> None:
    import os
    import signal

    from tests.processes import wait_for

    demo = subprocess.Popen(
        [sys.executable, "tools/demo.py", "--here", "--port", "0"],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    lines: list[str] = []
    try:
        wait_for(
            lambda: lines.append(demo.stdout.readline()) or "healthy" in lines[-1],
            60,
            "the demo to show a healthy bridge",
        )
        os.killpg(demo.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
        out, _ = demo.communicate(timeout=60)
    finally:
        if demo.poll() is None:
            os.killpg(demo.pid, signal.SIGKILL)
            demo.wait()
    assert demo.returncode == 0, "".join(lines) + out
    assert re.search(
        r"stopped: \d+ events queued in total, \d+ delivered, 0 left in the queue", out
    ), out
