"""The main job, end to end on embedded defaults: a simulated delivery robot through the
bridge. Creates and uses its own virtual environment (.venv-demo, runtime deps only).

    python3 tools/demo.py
"""

from __future__ import annotations

import subprocess
import sys

from bootstrap import ROOT, ensure_venv  # tools/bootstrap.py, beside this file


def main() -> int:
    python = ensure_venv(".venv-demo", ".")
    command = [str(python), "-m", "phytrace_edge", "sim", "--ticks", "300", *sys.argv[1:]]
    return subprocess.run(command, cwd=ROOT).returncode


if __name__ == "__main__":
    sys.exit(main())
