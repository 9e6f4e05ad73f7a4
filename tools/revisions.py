"""Two revisions side by side for ``tools/bench_startup.py`` and
``tools/bench_footprint.py``: ``--against REV`` (before) and ``--after REV`` (HEAD unless
given) are each checked out with ``git worktree`` into a temporary folder (removed
afterwards) and compiled to bytecode, and a bench runs each of its commands once from
each tree in turn, so that the machine's load falls on both alike.

A child selects its tree by ``PYTHONPATH`` (ahead of the editable install's path entry);
children run from the temporary folder, so that the current folder (``sys.path[0]`` of
``python -c`` and ``-m``) is never a tree, and each tree is checked once to be the one
imported. Without ``--against`` the one tree is the working tree, as before.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parent.parent


class Tree(NamedTuple):
    name: str  # "before", "after"; "tree" for the working tree alone
    revision: str  # as given (HEAD, b84e329, ...)
    commit: str  # its short hash, or "working tree"
    path: Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--against", metavar="REV", help="also measure REV (before), side by side, interleaved"
    )
    parser.add_argument(
        "--after", metavar="REV", default="HEAD", help="with --against: the after revision"
    )


def git(*args: str) -> str:
    return subprocess.run(
        ["git", "-C", str(ROOT), *args], check=True, capture_output=True, text=True
    ).stdout.strip()


def env(tree: Tree, **extra: str) -> dict[str, str]:
    """The environment of a child that runs ``tree``'s code (bytecode read, not written)."""
    found = {**os.environ, "PYTHONPATH": str(tree.path), **extra}
    found.pop("PYTHONDONTWRITEBYTECODE", None)
    return found


def check_imported(tree: Tree) -> None:
    """Fail unless a child with ``env(tree)`` imports ``phytrace_edge`` from ``tree``."""
    where = subprocess.run(
        [sys.executable, "-c", "import phytrace_edge; print(phytrace_edge.__file__)"],
        env=env(tree),
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    if not Path(where).resolve().is_relative_to(tree.path.resolve()):
        raise SystemExit(f"PYTHONPATH={tree.path} imported phytrace_edge from {where}")


@contextmanager
def trees(args: argparse.Namespace) -> Iterator[tuple[Path, list[Tree]]]:
    """(a temporary folder, now the current one; the trees): before and after with
    ``--against``, else the working tree; each compiled and checked."""
    workdir = Path(tempfile.mkdtemp(prefix="bench-revisions-"))
    made: list[Tree] = []
    here = Path.cwd()
    try:
        if args.against:
            for name, revision in (("before", args.against), ("after", args.after)):
                commit = git("rev-parse", "--short", f"{revision}^{{commit}}")
                git("worktree", "add", "--detach", "--quiet", str(workdir / name), commit)
                made.append(Tree(name, revision, commit, workdir / name))
            found = made
        else:
            found = [Tree("tree", "", "working tree", ROOT)]
        os.chdir(workdir)
        for tree in found:
            subprocess.run(
                [sys.executable, "-m", "compileall", "-q", str(tree.path / "phytrace_edge")],
                check=True,
            )
            check_imported(tree)
        yield workdir, found
    finally:
        os.chdir(here)
        for tree in made:
            git("worktree", "remove", "--force", str(tree.path))
        shutil.rmtree(workdir, ignore_errors=True)


def title(found: list[Tree]) -> str:
    """What was measured: "before b84e329 (b84e329), after 17d6409 (HEAD)"."""
    return ", ".join(f"{tree.name} {tree.commit} ({tree.revision})" for tree in found)


def ratio(before: float, after: float) -> str:
    return f"{after / before:.2f}x" if before else "–"
