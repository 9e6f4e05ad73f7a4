"""Install what the checks need into .venv and run every check: lint, format, types, tests.

    python3 tools/test.py            # everything
    python3 tools/test.py -k queue   # extra arguments go to pytest

Exits non-zero when any check fails. .ci/run calls exactly this.
"""

from __future__ import annotations

import subprocess
import sys

from bootstrap import ROOT, ensure_venv  # tools/bootstrap.py, beside this file

CHECKS = [
    ("ruff lint", ["-m", "ruff", "check", "."]),
    ("ruff format", ["-m", "ruff", "format", "--check", "."]),
    ("mypy", ["-m", "mypy"]),
]


def main() -> int:
    python = ensure_venv(".venv", ".[test]")
    failed = []
    for name, args in CHECKS:
        print(f"== {name}", flush=True)
        if subprocess.run([str(python), *args], cwd=ROOT).returncode != 0:
            failed.append(name)
    print("== pytest", flush=True)
    if subprocess.run([str(python), "-m", "pytest", *sys.argv[1:]], cwd=ROOT).returncode != 0:
        failed.append("pytest")
    if failed:
        print(f"FAILED: {', '.join(failed)}", flush=True)
        return 1
    print("all checks passed", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
