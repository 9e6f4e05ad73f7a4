"""Every repository path a comment or docstring cites exists: a reader sent to
``docs/queue.md`` or ``queue/timekeeping/clock.py`` finds it there, and a file that moves or goes
takes its citations along (in ``phytrace_edge/``, ``tests/`` and ``tools/``).

A cited path may be relative to the repository (``docs/udm.md``), to the package
(``runtime/wiring.py``), or to the citing file's folder or one above it (as the ingest
sources cite one another); a ``*`` is a glob, and ``module.NAME``
(``ship/tls.EXPIRY_WARNING_S``) cites the module. What ``.gitignore`` keeps out of the
repository (virtual environments, the demo's state) is made on the machine, and not
checked. A path outside the repository (the shared reference files beside it) is
refused: a clone, the wheel and the CI machines have only the repository, so a comment
says in its own words, or with the repository's docs, what such a file says."""

from __future__ import annotations

import ast
import fnmatch
import functools
import io
import itertools
import os
import re
import tokenize
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "phytrace_edge"
CITING = ("phytrace_edge", "tests", "tools")
SKIPPED = {"__pycache__", "node_modules"}
MADE_HERE = [  # the folders .gitignore lists: made on the machine, not in the repository
    line.strip().strip("/")
    for line in (ROOT / ".gitignore").read_text("utf-8").splitlines()
    if line.strip().endswith("/") and not line.startswith(("!", "#"))
]
# what a cited file ends with; other endings (stick1.mcap, queue.db) name examples
EXTENSIONS = {
    "conf", "env", "example", "html", "in", "js", "json", "md", "mjs", "png", "py",
    "service", "sh", "sql", "toml", "txt", "xml", "yaml", "yml", "zdict",
}  # fmt: skip
PATH = re.compile(r"(?<![\w./:~@$-])((?:\.\./)*[\w.][\w.-]*(?:/[\w.*-]+)+/?)")
ATTRIBUTE = re.compile(r"(.+/\w+)\.[A-Za-z_]\w*")  # ship/tls.EXPIRY_WARNING_S


def citing_files() -> Iterator[Path]:
    for top in CITING:
        for folder, subfolders, names in os.walk(ROOT / top):
            subfolders[:] = sorted(set(subfolders) - SKIPPED)
            for name in sorted(names):
                if name.endswith((".py", ".mjs")):
                    yield Path(folder, name)


def notes(path: Path) -> Iterator[tuple[int, str]]:
    """(line, text) of every comment and docstring of a source file."""
    source = path.read_text("utf-8")
    if path.suffix != ".py":  # JavaScript: // comments
        for number, line in enumerate(source.splitlines(), start=1):
            if "//" in line:
                yield number, line[line.index("//") + 2 :]
        return
    # a docstring is a string that is a statement of its own: after a NEWLINE, INDENT
    # or DEDENT (or first in the file), and followed by a NEWLINE
    before = tokenize.NEWLINE
    tokens = list(tokenize.generate_tokens(io.StringIO(source).readline))
    for token, after in itertools.pairwise(tokens):
        if token.type == tokenize.COMMENT:
            yield token.start[0], token.string
        elif (
            token.type == tokenize.STRING
            and token.string.lstrip("rRuU")[0] in "'\""  # not bytes, not an f-string
            and before in (tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT)
            and after.type == tokenize.NEWLINE
        ):
            for offset, line in enumerate(ast.literal_eval(token.string).splitlines()):
                yield token.start[0] + offset, line
        if token.type not in (tokenize.COMMENT, tokenize.NL):
            before = token.type


@functools.cache
def folders(path: Path) -> frozenset[str]:
    return frozenset(child.name for child in path.iterdir() if child.is_dir()) - SKIPPED


def cited(path: Path, text: str) -> Iterator[str]:
    """The paths ``text`` cites: those ending in a file's extension, and those that
    begin with a folder of the repository, of the package or beside ``path``."""
    known = folders(ROOT) | folders(PACKAGE) | folders(path.parent)
    for match in PATH.finditer(text):
        cite = match.group(1).rstrip(".,;:")
        if any(fnmatch.fnmatch(cite.split("/")[0], made) for made in MADE_HERE):
            continue
        last = cite.rstrip("/").rsplit("/", 1)[-1]
        extension = last.rsplit(".", 1)[-1] if "." in last else ""
        folder = cite.split("/")[0] in known and (
            "." not in last or ATTRIBUTE.fullmatch(cite) is not None or cite.endswith("/")
        )
        if cite.startswith("../") or extension in EXTENSIONS or folder:
            yield cite


def exists(path: Path, cite: str) -> bool:
    if cite.startswith("../"):
        return False  # outside the repository
    attribute = ATTRIBUTE.fullmatch(cite)
    if attribute and cite.rsplit(".", 1)[-1] not in EXTENSIONS:
        cite = attribute.group(1) + ".py"
    for base in (PACKAGE, *path.parents):
        if not base.is_relative_to(ROOT):
            break
        if "*" in cite:
            if any(base.glob(cite)):
                return True
        elif (base / cite).exists():
            return True
    return False


def false_citations() -> list[str]:
    found = []
    for path in citing_files():
        for line, text in notes(path):
            for cite in cited(path, text):
                if not exists(path, cite):
                    found.append(f"{path.relative_to(ROOT)}:{line}: {cite}")
    return found


def test_every_path_a_comment_or_docstring_cites_exists() -> None:
    assert false_citations() == []


def test_a_false_citation_is_found() -> None:
    """The check can fail: citations of files that are not there are reported, those
    of files that are, are not."""
    module = PACKAGE / "ingest" / "sources" / "ros.py"
    text = (
        "see docs/queue.md, queue/timekeeping/clock.py, ship/tls.EXPIRY_WARNING_S, "
        "tests/unit/*.py, "
        "docs/gone.md, queue/gone.py, phycloud_edge/x.py, ../shared/reference/guide.txt, "
        "tests/unit/test_gone_*.py, sensor_msgs/msg/Imu (a ROS type), .venv/bin/python "
        "and sources/sim.py"
    )
    assert [cite for cite in cited(module, text) if not exists(module, cite)] == [
        "docs/gone.md",
        "queue/gone.py",
        "phycloud_edge/x.py",
        "../shared/reference/guide.txt",
        "tests/unit/test_gone_*.py",
    ]
