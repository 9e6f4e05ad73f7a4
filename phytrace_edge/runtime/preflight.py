"""Checks at start that warn an operator about a setup that will lose data later."""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from pathlib import Path

log = logging.getLogger(__name__)

# Docker's local volumes live at .../volumes/<name>/_data; a volume made for an image's
# VOLUME without `-v` (anonymous) is named by 64 hex digits.
_ANONYMOUS_VOLUME = re.compile(r"/volumes/[0-9a-f]{64}/_data$")


def mounts(mountinfo: str) -> dict[str, str]:
    """Mount point -> the root of the mount within its file system, from the text of
    ``/proc/self/mountinfo`` (octal escapes such as ``\\040`` decoded)."""

    def decode(field: str) -> str:
        return re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), field)

    found = {}
    for line in mountinfo.splitlines():
        fields = line.split()
        if len(fields) > 4:
            found[decode(fields[4])] = decode(fields[3])
    return found


def warn_if_not_on_a_volume(
    queue_path: Path, env: Mapping[str, str], mountinfo: str | None = None
) -> str | None:
    """In the container, a queue that is not on a volume dies with the container, and
    one on an anonymous volume (``VOLUME`` without ``-v``) is not found again by the
    next container: say so loudly. What was wrong (``"no volume"``, ``"anonymous"``),
    or None."""
    if not env.get("PHYTRACE_CONTAINER"):
        return None
    if mountinfo is None:
        try:
            mountinfo = Path("/proc/self/mountinfo").read_text()
        except OSError:
            return None
    folder = queue_path.resolve().parent
    points = mounts(mountinfo)
    mount = next((p for p in (folder, *folder.parents) if str(p) in points), None)
    advice = (
        f"Mount a named volume at {folder} (docker run -v phytrace-queue:{folder}, or "
        "compose's volumes)"
    )
    if mount is None or str(mount) == "/":
        log.warning(
            "!!! the queue %s is not on a mounted volume: the backlog will be lost with the "
            "container. %s !!!",
            queue_path,
            advice,
        )
        return "no volume"
    if _ANONYMOUS_VOLUME.search(points[str(mount)]):
        log.warning(
            "!!! the queue %s is on an anonymous volume (no -v was given): a new container "
            "starts with an empty queue, and docker rm -v or --rm deletes the backlog. %s !!!",
            queue_path,
            advice,
        )
        return "anonymous"
    return None
