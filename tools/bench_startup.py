"""Start-up cost of the commands an operator and a health check run, side by side with
the floor: a bare ``python -c pass`` from the same virtual environment.

    .venv/bin/python tools/bench_startup.py          # 100k-event queue, 15 runs each
    .venv/bin/python tools/bench_startup.py --events 10000 --runs 5

Each command runs in a fresh process, interleaved with the others; the table shows the
median wall time and the peak RSS (from wait4) and their ratio to the floor. The
container's health check runs ``status`` every 30 s, so its cost is paid all day.
A child's peak RSS counts its parent's memory at fork, so each command is started by a
small launcher process (a bare Python, no larger than the floor itself) that times it
and reads its peak RSS from wait4. The project is compiled to bytecode first, as an
installed wheel is (PYTHONDONTWRITEBYTECODE would make every start compile it).

    .venv/bin/python tools/bench_startup.py --against b84e329 [--after HEAD]

measures two revisions side by side in one run (``tools/revisions.py``): each command
once from each tree in turn, each tree on its own queue filled by its own code; the
table shows both and the ratio after/before. On a loaded machine the wall times of one
run spread by 5-10 %; ``--instructions`` adds each command's count of user-space
instructions, once under valgrind's callgrind (``PYTHONHASHSEED=0``), which is the same
on a loaded machine as on an idle one.
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
from pathlib import Path

import revisions  # tools/, beside this file

FILL = """
import sys, uuid
from phytrace_edge.queue.store import QueueStore
try:  # put_many takes Built (event, important) since phytrace_edge.udm.types
    from phytrace_edge.udm.types import Built
    wrap = lambda event: Built(event, False)
except ImportError:  # before: plain events
    wrap = lambda event: event
path, events = sys.argv[1], int(sys.argv[2])
with QueueStore.open(path, sync="normal") as store:
    for start in range(0, events, 1000):
        store.put_many([
            wrap({"event_id": str(uuid.uuid4()), "seq": seq, "pad": "x" * 1500})
            for seq in range(start, min(events, start + 1000))
        ])
"""


LAUNCHER = """
import os, sys, time
started = time.perf_counter()
pid = os.fork()
if pid == 0:
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    os.execv(sys.argv[1], sys.argv[1:])
_, status, usage = os.wait4(pid, 0)
print(time.perf_counter() - started, usage.ru_maxrss)
"""


def measure(command: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall seconds, peak RSS MiB) of one run of ``command``."""
    out = subprocess.run(
        [sys.executable, "-c", LAUNCHER, *command], env=env, capture_output=True, text=True
    ).stdout.split()
    return float(out[0]), int(out[1]) / 1024


def instructions(command: list[str], env: dict[str, str]) -> int:
    """User-space instructions of one run of ``command`` (valgrind's callgrind)."""
    result = subprocess.run(
        ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", *command],
        env={**env, "PYTHONHASHSEED": "0"},
        capture_output=True,
        text=True,
        check=False,  # status exits non-zero when no bridge runs: counted all the same
    )
    found = re.search(r"Collected : (\d+)", result.stderr)
    if not found:
        raise SystemExit(f"no instruction count from callgrind:\n{result.stderr}")
    return int(found.group(1))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--events", type=int, default=100_000, help="events in the queue")
    parser.add_argument("--runs", type=int, default=15, help="runs of each command")
    parser.add_argument(
        "--instructions", action="store_true", help="also count instructions (valgrind)"
    )
    revisions.add_arguments(parser)
    args = parser.parse_args()
    python = sys.executable
    script = str(Path(python).with_name("phytrace-edge"))  # what the health check runs
    commands = {
        "python -c pass (floor)": [python, "-c", "pass"],
        "phytrace-edge status --json": [script, "status", "--json"],
        "phytrace-edge --help": [script, "--help"],
        "phytrace-edge config": [script, "config"],
        "python -m phytrace_edge status --json": [
            python,
            "-m",
            "phytrace_edge",
            "status",
            "--json",
        ],
    }
    with revisions.trees(args) as (workdir, trees):
        envs = []
        for tree in trees:
            queue = workdir / f"queue-{tree.name}.db"
            print(f"filling a queue with {args.events} events ({tree.commit}) ...", flush=True)
            envs.append(revisions.env(tree, QUEUE_PATH=str(queue)))
            subprocess.run(
                [python, "-c", FILL, str(queue), str(args.events)], env=envs[-1], check=True
            )
        # samples[command][tree]: each command once from each tree in turn, the order
        # of the trees reversed every other run
        samples: dict[str, list[list[tuple[float, float]]]] = {
            name: [[] for _ in trees] for name in commands
        }
        for run in range(args.runs):
            for name, command in commands.items():
                order = range(len(trees)) if run % 2 == 0 else reversed(range(len(trees)))
                for i in order:
                    samples[name][i].append(measure(command, envs[i]))
        counts: dict[str, list[int]] = {}
        if args.instructions:  # once per command and tree: the count does not vary
            for name, command in commands.items():
                counts[name] = [instructions(command, env) for env in envs]
    print(f"\n{args.events} events queued, median of {args.runs} runs each, interleaved")
    if len(trees) > 1:
        print(f"({revisions.title(trees)})\n")
        print_compared(samples)
    else:
        print()
        print_against_floor({name: runs[0] for name, runs in samples.items()})
    if counts:
        print_instructions(counts)
    return 0


def medians(runs: list[tuple[float, float]]) -> tuple[float, float]:
    """(median wall seconds, median peak RSS MiB)."""
    return statistics.median(w for w, _ in runs), statistics.median(r for _, r in runs)


def print_against_floor(samples: dict[str, list[tuple[float, float]]]) -> None:
    floor_wall, floor_rss = medians(samples["python -c pass (floor)"])
    print("| command | wall | ratio to floor | peak RSS | ratio to floor |")
    print("|---|---|---|---|---|")
    for name, runs in samples.items():
        wall, rss = medians(runs)
        print(
            f"| `{name}` | {wall * 1000:.0f} ms | {wall / floor_wall:.2f}x | "
            f"{rss:.1f} MiB | {rss / floor_rss:.2f}x |"
        )


def print_compared(samples: dict[str, list[list[tuple[float, float]]]]) -> None:
    print(
        "| command | wall before | after | after/before | peak RSS before | after | after/before |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, (before, after) in samples.items():
        (wall_b, rss_b), (wall_a, rss_a) = medians(before), medians(after)
        print(
            f"| `{name}` | {wall_b * 1000:.1f} ms | {wall_a * 1000:.1f} ms | "
            f"{revisions.ratio(wall_b, wall_a)} | {rss_b:.1f} MiB | {rss_a:.1f} MiB | "
            f"{revisions.ratio(rss_b, rss_a)} |"
        )


def print_instructions(counts: dict[str, list[int]]) -> None:
    """Millions of instructions per command: per tree, and after/before or to the floor."""
    floor = counts["python -c pass (floor)"][0]
    trees = len(next(iter(counts.values())))
    heads = "before | after | after/before" if trees > 1 else "count | ratio to floor"
    print(f"\n| command | instructions (millions), {heads} |")
    print("|---|---|---|---|" if trees > 1 else "|---|---|---|")
    for name, found in counts.items():
        cells = [f"{count / 1e6:.1f}" for count in found]
        cells.append(revisions.ratio(*found) if trees > 1 else f"{found[0] / floor:.2f}x")
        print(f"| `{name}` | {' | '.join(cells)} |")


if __name__ == "__main__":
    sys.exit(main())
