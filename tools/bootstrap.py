"""Create or refresh a project virtual environment (stdlib only: runs on a bare Python 3.10+).

Used by tools/test.py and tools/demo.py. The environment is reinstalled when
pyproject.toml changes (its hash is kept in the venv), so a fresh clone and a stale
checkout both end up with exactly what the project declares.
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def ensure_venv(name: str, install_target: str) -> Path:
    """The venv ``ROOT/name`` with ``pip install -e <install_target>`` done; its python."""
    if sys.version_info < (3, 10):  # noqa: UP036 - this script runs on any python3
        sys.exit(f"phytrace-edge needs Python 3.10 or newer; this is {sys.version.split()[0]}")
    env_dir = ROOT / name
    python = env_dir / "bin" / "python"
    if not python.exists():
        print(f"creating virtual environment {env_dir} ...", flush=True)
        venv.EnvBuilder(with_pip=True, clear=True).create(env_dir)
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes() + install_target.encode())
    stamp = env_dir / ".phytrace-installed"
    if not stamp.exists() or stamp.read_text() != digest.hexdigest():
        print(f"installing {install_target} into {env_dir} ...", flush=True)
        subprocess.run(
            [str(python), "-m", "pip", "install", "--quiet", "--upgrade", "pip"], check=True
        )
        subprocess.run(
            [str(python), "-m", "pip", "install", "--quiet", "-e", install_target],
            check=True,
            cwd=ROOT,
        )
        stamp.write_text(digest.hexdigest())
    return python
