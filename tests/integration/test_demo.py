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
