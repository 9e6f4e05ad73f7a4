"""Checks at start that warn an operator about a setup that will lose data later."""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from pathlib import Path

log = logging.getLogger(__name__)


def warn_if_not_on_a_volume(queue_path: Path, env: Mapping[str, str]) -> bool:
    """In the container, a queue that is not on a mounted volume dies with the container
    and takes the backlog with it: say so loudly. True when it warned."""
    if not env.get("PHYTRACE_CONTAINER"):
        return False
    folder = queue_path.resolve().parent
    if any(os.path.ismount(p) for p in (folder, *folder.parents) if str(p) != "/"):
        return False
    log.warning(
        "!!! the queue %s is not on a mounted volume: the backlog will be lost with the "
        "container. Mount a volume at %s (docker run -v phytrace-queue:%s, or compose's "
        "volumes) !!!",
        queue_path,
        folder,
        folder,
    )
    return True
