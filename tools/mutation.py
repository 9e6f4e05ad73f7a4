"""Mutation testing of the ship and queue stages (mutmut 3), in a snapshot of a commit.

The tool is not one of the project's installs (CI does not run it; the score is a figure
in docs/benchmarks.md, not a gate). Put it into the test venv first:

    .venv/bin/python -m pip install 'mutmut==3.8.1'

Then, from the repository root:

    .venv/bin/python tools/mutation.py --max-children 2

It runs at nice 10, so that other work on the machine goes first. The whole of ship/ and
queue/ is 6,500 mutants and takes many hours on the 2-core machine (a surviving mutant
of the store runs ~130 tests); ``--mutate`` narrows it, ``--keep`` and ``--resume`` let
a stopped run go on. docs/benchmarks.md has the run made, its scope and its figures.

What it does:

1. ``git worktree add --detach TREE REF`` (default ``/tmp/phytrace-mutation`` at HEAD): the
   tool mutates and tests a snapshot, never the work tree, so edits under way there can
   neither disturb the run nor be disturbed by it. ``--with PATH`` copies files of the work
   tree that are not committed yet (new tests, say) into the snapshot.
2. Writes mutmut's configuration into the snapshot's pyproject.toml (``[tool.mutmut]``):
   every module of ``phytrace_edge/ship/`` and ``phytrace_edge/queue/`` is mutated
   (``--mutate`` narrows it); the tests are ``tests/unit``, but test_startup.py (it checks
   what a command's process imports, and mutated code imports mutmut). mutmut runs that
   selection once to learn which tests call which function and then, for each mutant,
   only the tests that reached the mutated function (fastest first, stopping at the
   first failure). The slower suites (integration, network, chaos, hostile, container)
   are not part of the selection: they start processes, whose calls mutmut does not
   see, and take ~20 minutes.
3. Runs ``mutmut run`` in the snapshot (``mutants/`` is written there, not here) with
   ``PYTHONPATH`` on the snapshot, so that a test's child process runs the snapshot's
   code, not this work tree's (the venv's editable install points here).
4. Prints the score, killed / total, and the survivors by module, and writes them to
   ``mutation-summary.json`` in the tree.
5. Removes the snapshot unless ``--keep``. With ``--keep``, ``mutmut show NAME`` and
   ``mutmut browse`` in ``TREE`` show a survivor's diff.

Again, after adding tests, only the mutants that survived (in a kept snapshot; ``--named``
narrows them to some modules):

    .venv/bin/python tools/mutation.py --keep --again survived \
        --with tests/unit/test_sender_batching.py --named 'phytrace_edge.ship.sender.*'

``--report`` prints the summary of a kept snapshot without running anything.

A sample, when the whole scope would take too long (all of queue/ is ~6,500 mutants): the
mutants are generated, then a seeded random share of each module's is tested, and the
summary counts only those (a mutant not drawn is not a result):

    .venv/bin/python tools/mutation.py --max-children 2 --keep \
        --mutate 'phytrace_edge/queue/*' --sample 0.06 --seed 34
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import random
import shutil
import subprocess
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_TREE = Path("/tmp/phytrace-mutation")
MUTATED = ["phytrace_edge/ship/*", "phytrace_edge/queue/*"]
# test_startup checks what a command's process imports: mutated code imports mutmut
TESTS = ["tests/unit", "--ignore=tests/unit/test_startup.py"]

# mutmut's exit codes (its stats module) as the statuses this script counts
STATUS = {
    1: "killed",
    3: "killed",
    0: "survived",
    5: "no tests",
    33: "no tests",
    34: "skipped",
    35: "suspicious",
    36: "timeout",
    37: "caught by type check",
    -24: "timeout",
    24: "timeout",
    152: "timeout",
    255: "timeout",
    -11: "crashed",
    -9: "crashed",
    2: "interrupted",
    None: "not checked",
}
CAUGHT = ("killed", "caught by type check", "timeout", "crashed")
TABLE = "\n[tool.mutmut]\n"
# what mutmut does not copy into the tree's mutants folder: the package (mutated
# there), its own output
NOT_COPIED = {
    "phytrace_edge",
    "mutants",
    ".git",
    ".hypothesis",
    "mutmut.log",
    "mutation-summary.json",
}


def mutmut_config(tree: Path, mutated: list[str], tests: list[str]) -> str:
    """The ``[tool.mutmut]`` table appended to the snapshot's pyproject.toml."""
    # mutmut runs the tests in the tree's mutants folder: the rest of the repository goes there too
    # (tests read docs/, migrations/, .gitignore, ...)
    copied = sorted(
        entry.name + ("/" if entry.is_dir() else "")
        for entry in tree.iterdir()
        if entry.name not in NOT_COPIED
    )
    table = {
        "source_paths": ["phytrace_edge"],
        "only_mutate": mutated,
        "also_copy": copied,
        "pytest_add_cli_args_test_selection": tests,
        "pytest_add_cli_args": ["-p", "no:cacheprovider"],
        "use_git_change_detection": False,
    }
    lines = ["", TABLE.strip()]
    lines += [f"{key} = {json.dumps(value)}" for key, value in table.items()]
    return "\n".join(lines) + "\n"


def make_snapshot(tree: Path, ref: str, extra: list[str]) -> None:
    if tree.exists():
        raise SystemExit(f"{tree} exists: remove it (git worktree remove --force) or --resume")
    subprocess.run(
        ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), ref],
        check=True,
    )
    copy_extra(tree, extra)


def write_config(tree: Path, mutated: list[str], tests: list[str]) -> None:
    """Put (or replace) mutmut's table at the end of the snapshot's pyproject.toml. A
    narrower ``only_mutate`` keeps what mutmut learnt of the tests (its stats)."""
    pyproject = tree / "pyproject.toml"
    text = pyproject.read_text(encoding="utf-8").split(TABLE)[0].rstrip("\n") + "\n"
    pyproject.write_text(text + mutmut_config(tree, mutated, tests), encoding="utf-8")


def scope(tree: Path) -> list[str]:
    """The files the snapshot's mutmut table mutates."""
    text = (tree / "pyproject.toml").read_text(encoding="utf-8")
    return list(tomllib.loads(text)["tool"]["mutmut"]["only_mutate"])


def copy_extra(tree: Path, extra: list[str]) -> None:
    for name in extra:
        source = (ROOT / name).resolve()
        target = tree / source.relative_to(ROOT)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(source, target)
        print(f"copied {name} into the snapshot")


def statuses(tree: Path) -> dict[str, dict[str, str]]:
    """Every mutant's status, by module (from mutmut's ``.meta`` files)."""
    by_module: dict[str, dict[str, str]] = {}
    globs = scope(tree)
    for meta in sorted((tree / "mutants").rglob("*.py.meta")):
        module = str(meta.relative_to(tree / "mutants"))[: -len(".meta")]
        if not any(fnmatch.fnmatch(module, glob) for glob in globs):
            continue  # left from a run of a wider scope
        codes = json.loads(meta.read_text(encoding="utf-8"))["exit_code_by_key"]
        if codes:
            by_module[module] = {key: STATUS.get(code, "suspicious") for key, code in codes.items()}
    return by_module


def draw_sample(tree: Path, share: float, seed: int) -> list[str]:
    """A seeded random share of each module's mutants (at least one per module), so that
    a small module is not left out of the figure by chance."""
    draw = random.Random(seed)
    names: list[str] = []
    for found in statuses(tree).values():
        keys = sorted(found)
        names += draw.sample(keys, max(1, round(len(keys) * share)))
    return sorted(names)


def generate(tree: Path, max_children: int) -> None:
    """Let mutmut write the mutants and learn which tests reach each function, testing no
    mutant: it is given a name no mutant has, and stops on finding none."""
    run_mutmut(tree, max_children, ["phytrace-edge-no-such-mutant"], expect_failure=True)


def summary(tree: Path) -> dict[str, object]:
    """Counts of the mutants with a result; one not checked (stopped, or not drawn) is
    counted apart, never as caught."""
    everything = statuses(tree)
    not_checked = sum(s == "not checked" for found in everything.values() for s in found.values())
    by_module = {
        module: checked
        for module, found in everything.items()
        if (checked := {k: s for k, s in found.items() if s != "not checked"})
    }
    totals: Counter[str] = Counter()
    survivors: dict[str, list[str]] = defaultdict(list)
    rows = []
    for module, found in by_module.items():
        counts = Counter(found.values())
        totals.update(counts)
        survivors[module] = sorted(k for k, s in found.items() if s == "survived")
        caught = sum(counts[s] for s in CAUGHT)
        rows.append((module, len(found), caught, counts["survived"], counts["no tests"]))
    total = sum(totals.values())
    caught = sum(totals[s] for s in CAUGHT)
    return {
        "total": total,
        "caught": caught,
        "score": round(caught / total, 4) if total else None,
        "by_status": dict(totals),
        "not_checked": not_checked,
        "modules": [
            {"module": m, "mutants": n, "caught": c, "survived": s, "no_tests": nt}
            for m, n, c, s, nt in rows
        ],
        "survivors": {m: names for m, names in survivors.items() if names},
    }


def print_summary(result: dict[str, object]) -> None:
    by_status = result["by_status"]
    assert isinstance(by_status, dict)
    print(f"\nmutants with a result: {result['total']} (not checked: {result['not_checked']})")
    for status, count in sorted(by_status.items(), key=lambda item: -item[1]):
        print(f"  {status:22} {count}")
    score = result["score"]
    print(f"score: {result['caught']} / {result['total']} caught = {score:.1%}" if score else "")
    print(f"\n{'module':55} {'mutants':>7} {'caught':>7} {'survived':>8} {'no tests':>8}")
    modules = result["modules"]
    assert isinstance(modules, list)
    for row in modules:
        print(
            f"{row['module']:55} {row['mutants']:>7} {row['caught']:>7}"
            f" {row['survived']:>8} {row['no_tests']:>8}"
        )


def run_mutmut(
    tree: Path, max_children: int, names: list[str], expect_failure: bool = False
) -> float:
    mutmut = Path(sys.executable).with_name("mutmut")
    if not mutmut.exists():
        raise SystemExit("mutmut is not installed: .venv/bin/python -m pip install 'mutmut==3.8.1'")
    env = dict(os.environ, PYTHONPATH=str(tree), PYTHONHASHSEED="0")
    log = tree / "mutmut.log"
    command = [str(mutmut), "run", "--max-children", str(max_children), *names]
    print(f"running {' '.join(command[1:4])} ... in {tree} (log: {log})", flush=True)
    start = time.monotonic()
    with log.open("ab") as out:
        code = subprocess.run(command, cwd=tree, env=env, stdout=out, stderr=subprocess.STDOUT)
    took = time.monotonic() - start
    print(f"mutmut ran for {took / 60:.1f} min (exit {code.returncode})")
    if code.returncode != 0 and not expect_failure:
        print(log.read_text(encoding="utf-8", errors="replace")[-3000:])
        raise SystemExit(code.returncode)
    return took


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tree", type=Path, default=DEFAULT_TREE, help="where the snapshot goes")
    parser.add_argument("--ref", default="HEAD", help="the commit to snapshot")
    parser.add_argument(
        "--with",
        dest="extra",
        action="append",
        default=[],
        metavar="PATH",
        help="a file of the work tree to copy into the snapshot (repeatable)",
    )
    parser.add_argument("--max-children", type=int, default=1, help="mutants tested at once")
    parser.add_argument("--nice", type=int, default=10, help="niceness of the run")
    parser.add_argument(
        "--mutate",
        action="append",
        metavar="GLOB",
        help=f"files to mutate (default: {' '.join(MUTATED)})",
    )
    parser.add_argument(
        "--tests",
        action="append",
        metavar="PYTEST_ARG",
        help=f"the test selection (default: {' '.join(TESTS)})",
    )
    parser.add_argument(
        "--again",
        metavar="STATUS",
        help="in a kept snapshot, test again the mutants of this status "
        "(e.g. survived), after copying in --with files",
    )
    parser.add_argument(
        "--named",
        action="append",
        metavar="GLOB",
        help="with --again: only mutants whose name matches (e.g. 'phytrace_edge.ship.sender.*')",
    )
    parser.add_argument(
        "--resume",
        action="store_true",
        help="go on with a kept snapshot's run (mutants with a result are not run again); "
        "with --mutate, over those files",
    )
    parser.add_argument("--keep", action="store_true", help="leave the snapshot in place")
    parser.add_argument(
        "--report", action="store_true", help="print a kept snapshot's summary only"
    )
    parser.add_argument(
        "--sample",
        type=float,
        metavar="SHARE",
        help="test a seeded random share (0-1] of each module's mutants, not all of them",
    )
    parser.add_argument("--seed", type=int, default=34, help="the sample's seed")
    args = parser.parse_args()
    tree: Path = args.tree.resolve()
    if args.sample is not None and not 0 < args.sample <= 1:
        parser.error("--sample is a share of the mutants, more than 0 and at most 1")

    if args.report:
        print_summary(summary(tree))
        return 0
    os.nice(args.nice)
    mutated, tests = args.mutate or MUTATED, args.tests or TESTS
    names: list[str] = []
    if args.again:
        copy_extra(tree, args.extra)
        names = [
            key
            for found in statuses(tree).values()
            for key, status in found.items()
            if status == args.again
            and (not args.named or any(fnmatch.fnmatch(key, glob) for glob in args.named))
        ]
        if not names:
            print(f"no mutant is {args.again}")
            return 0
        print(f"testing again {len(names)} mutants that were {args.again}")
    elif args.resume:
        copy_extra(tree, args.extra)
        if args.mutate or args.tests:
            write_config(tree, mutated, tests)
    else:
        make_snapshot(tree, args.ref, args.extra)
        write_config(tree, mutated, tests)
    try:
        if args.sample is not None:
            generate(tree, args.max_children)
            names = draw_sample(tree, args.sample, args.seed)
            print(f"testing {len(names)} mutants drawn (share {args.sample}, seed {args.seed})")
        took = run_mutmut(tree, args.max_children, names)
        result = summary(tree)
        result["minutes"] = round(took / 60, 1)
        (tree / "mutation-summary.json").write_text(json.dumps(result, indent=2), encoding="utf-8")
        print_summary(result)
    finally:
        if not args.keep:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
