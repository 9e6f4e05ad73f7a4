"""A stand-in for ``ros:jazzy-ros-base``, made on this machine (no registry is reachable
here): ``debootstrap --variant=minbase`` of Debian bookworm with Python and systemd,
the host's CA bundle (pip inside ``docker build`` goes through the same TLS path as the
host's), ROS's ``/ros_entrypoint.sh`` and an empty ``/opt/ros/jazzy/setup.bash``,
imported with ``docker import``.

The image is tagged by a content key (this file, the package list, the CA bundle), so a
rerun on the same machine finds it and takes seconds. Run as a script to build it
ahead (``.ci/run`` does, with a progress line): ``python3 tests/container/standin.py``.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SUITE = "bookworm"
MIRROR = "http://deb.debian.org/debian"
PACKAGES = (
    "python3",
    "python3-venv",
    "ca-certificates",
    "systemd",
    "systemd-sysv",
    "dbus",
    "sudo",
    "procps",
)
CA_BUNDLE = Path("/etc/ssl/certs/ca-certificates.crt")
ENTRYPOINT = '#!/bin/bash\nset -e\nsource /opt/ros/jazzy/setup.bash\nexec "$@"\n'
REPOSITORY = "phytrace-standin"


def content_key() -> str:
    digest = hashlib.sha256(Path(__file__).read_bytes())
    digest.update(" ".join(PACKAGES).encode())
    if CA_BUNDLE.exists():
        digest.update(CA_BUNDLE.read_bytes())
    return digest.hexdigest()[:16]


def image_tag() -> str:
    return f"{REPOSITORY}:{content_key()}"


def exists(tag: str) -> bool:
    return subprocess.run(["docker", "image", "inspect", tag], capture_output=True).returncode == 0


def build(log=sys.stderr) -> str:
    """The stand-in base image's tag, built unless this machine has it already."""
    tag = image_tag()
    if exists(tag):
        return tag
    if shutil.which("debootstrap") is None:
        raise RuntimeError("debootstrap is not installed (apt-get install debootstrap)")
    work = Path(tempfile.mkdtemp(prefix="phytrace-standin-", dir="/var/tmp"))
    rootfs = work / "rootfs"
    try:
        print(f"debootstrap {SUITE} into {rootfs} (a few minutes) ...", file=log, flush=True)
        subprocess.run(
            [
                "debootstrap",
                "--variant=minbase",
                f"--include={','.join(PACKAGES)}",
                SUITE,
                str(rootfs),
                MIRROR,
            ],
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            timeout=1200,
        )
        (rootfs / "ros_entrypoint.sh").write_text(ENTRYPOINT)
        (rootfs / "ros_entrypoint.sh").chmod(0o755)
        (rootfs / "opt/ros/jazzy").mkdir(parents=True, exist_ok=True)
        (rootfs / "opt/ros/jazzy/setup.bash").write_text("# stand-in: no ROS here\n")
        if CA_BUNDLE.exists():
            shutil.copyfile(CA_BUNDLE, rootfs / "etc/ssl/certs/ca-certificates.crt")
        shutil.rmtree(rootfs / "var/cache/apt/archives", ignore_errors=True)
        tar = subprocess.Popen(["tar", "-C", str(rootfs), "-c", "."], stdout=subprocess.PIPE)
        subprocess.run(
            ["docker", "import", "--change", 'CMD ["/bin/bash"]', "-", tag],
            stdin=tar.stdout,
            check=True,
            stdout=subprocess.DEVNULL,
            timeout=600,
        )
        if tar.wait(timeout=60) != 0:
            raise RuntimeError("tar of the stand-in root file system failed")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return tag


if __name__ == "__main__":
    print(build())
