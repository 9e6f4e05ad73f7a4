"""Install what the checks need into .venv and run every check: lint, format, types, tests.

    python3 tools/test.py            # everything
    python3 tools/test.py -k queue   # extra arguments go to pytest

Exits non-zero when any check fails. .ci/run calls exactly this.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from bootstrap import ROOT, ensure_venv  # tools/bootstrap.py, beside this file

NODE_READER = ROOT / "tests" / "integration" / "mcap_reader"

CHECKS = [
    ("ruff lint", ["-m", "ruff", "check", "."]),
    ("ruff format", ["-m", "ruff", "format", "--check", "."]),
    ("mypy", ["-m", "mypy"]),
]


def install_real_rclpy() -> None:
    """Real rclpy from the package index, a venv per ROS 2 distribution (their wheels
    conflict): .venv-jazzy (the jazzy extra, the product's distro) and .venv-kilted
    (the kilted extra, with colcon and ament_cmake to build the bridge as a ROS
    package), for tests/ros. Where the wheels cannot install (x86_64 only), those tests
    say why and skip; in CI they fail instead."""
    for venv, extras in ((".venv-jazzy", ".[jazzy]"), (".venv-kilted", ".[kilted,ros-build]")):
        try:
            ensure_venv(venv, extras)
        except subprocess.CalledProcessError as exc:
            print(f"warning: the ROS 2 wheels ({extras}) did not install ({exc}); tests/ros skip")


def install_node_reader() -> None:
    """The npm packages of the independent MCAP reader (tests/integration/mcap_reader),
    exactly as its package-lock.json says, without install scripts. Without npm that
    test says why and skips; in CI it fails instead."""
    npm = shutil.which("npm")
    if npm is None:
        print("warning: npm is not installed; the independent MCAP reader test will skip")
        return
    installed = NODE_READER / "node_modules" / ".package-lock.json"
    lock = NODE_READER / "package-lock.json"
    if installed.exists() and installed.stat().st_mtime >= lock.stat().st_mtime:
        return
    command = [npm, "ci", "--no-audit", "--no-fund", "--ignore-scripts", "--loglevel=error"]
    if subprocess.run(command, cwd=NODE_READER).returncode != 0:
        print("warning: npm ci failed; the independent MCAP reader test will skip")


def run_pytest(python: str, args: list[str]) -> bool:
    """The tests; with no arguments, those marked ``paced`` (which wait on real time,
    using little CPU) in a process beside the rest, so that CI's time is not the sum.
    Their output follows the others'."""
    if args:
        return subprocess.run([python, "-m", "pytest", *args], cwd=ROOT).returncode == 0
    with tempfile.TemporaryDirectory(prefix="phytrace-paced-") as scratch:
        log_path = Path(scratch) / "paced.log"
        with log_path.open("w") as log:
            paced = subprocess.Popen(
                [python, "-m", "pytest", "-m", "paced", f"--basetemp={scratch}/tmp"],
                cwd=ROOT,
                stdout=log,
                stderr=subprocess.STDOUT,
            )
            try:
                rest = subprocess.run([python, "-m", "pytest", "-m", "not paced"], cwd=ROOT)
            finally:
                paced_code = paced.wait()
        print("== pytest (paced, run beside the rest)", flush=True)
        print(log_path.read_text(), flush=True)
    return rest.returncode == 0 and paced_code == 0


def main() -> int:
    python = ensure_venv(".venv", ".[test]")
    install_real_rclpy()
    install_node_reader()
    failed = []
    for name, args in CHECKS:
        print(f"== {name}", flush=True)
        if subprocess.run([str(python), *args], cwd=ROOT).returncode != 0:
            failed.append(name)
    print("== pytest", flush=True)
    if not run_pytest(str(python), sys.argv[1:]):
        failed.append("pytest")
    if failed:
        print(f"FAILED: {', '.join(failed)}", flush=True)
        return 1
    print("all checks passed", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
