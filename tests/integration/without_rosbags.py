"""``phytrace-edge ARGS`` as on a machine where rosbags is not installed (only the dds
extra, say): ``import rosbags`` fails as it does there, whether rosbags is in this
Python or not; everything else is the real command.

    python without_rosbags.py run --input dds
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import runpy
import sys
from collections.abc import Sequence
from types import ModuleType


class NoRosbags(importlib.abc.MetaPathFinder):
    """Finds rosbags and its modules nowhere, before any other finder looks."""

    def find_spec(
        self,
        fullname: str,
        path: Sequence[str] | None = None,
        target: ModuleType | None = None,
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname == "rosbags" or fullname.startswith("rosbags."):
            raise ModuleNotFoundError(f"No module named {fullname!r}", name=fullname)
        return None


if __name__ == "__main__":
    sys.meta_path.insert(0, NoRosbags())
    sys.argv = ["phytrace-edge", *sys.argv[1:]]
    runpy.run_module("phytrace_edge", run_name="__main__", alter_sys=True)
