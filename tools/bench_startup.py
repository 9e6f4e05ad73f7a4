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
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


FILL = """
import sys, uuid
from phytrace_edge.queue.store import QueueStore
path, events = sys.argv[1], int(sys.argv[2])
with QueueStore.open(path, sync="normal") as store:
    for start in range(0, events, 1000):
        store.put_many([
            {"event_id": str(uuid.uuid4()), "seq": seq, "pad": "x" * 1500}
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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--events", type=int, default=100_000, help="events in the queue")
    parser.add_argument("--runs", type=int, default=15, help="runs of each command")
    args = parser.parse_args()
    python = sys.executable
    script = str(Path(python).with_name("phytrace-edge"))  # what the health check runs
    with tempfile.TemporaryDirectory() as tmp:
        queue = Path(tmp) / "queue.db"
        print(f"filling a queue with {args.events} events ...", flush=True)
        env = {**os.environ, "QUEUE_PATH": str(queue), "PYTHONPATH": str(ROOT)}
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        subprocess.run([python, "-c", FILL, str(queue), str(args.events)], env=env, check=True)
        subprocess.run([python, "-m", "compileall", "-q", str(ROOT / "phytrace_edge")], check=True)
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
        samples: dict[str, list[tuple[float, float]]] = {name: [] for name in commands}
        for _ in range(args.runs):
            for name, command in commands.items():
                samples[name].append(measure(command, env))
    floor_wall = statistics.median(w for w, _ in samples["python -c pass (floor)"])
    floor_rss = statistics.median(r for _, r in samples["python -c pass (floor)"])
    print(f"\n{args.events} events queued, median of {args.runs} runs each, interleaved\n")
    print("| command | wall | ratio to floor | peak RSS | ratio to floor |")
    print("|---|---|---|---|---|")
    for name, runs in samples.items():
        wall = statistics.median(w for w, _ in runs)
        rss = statistics.median(r for _, r in runs)
        print(
            f"| `{name}` | {wall * 1000:.0f} ms | {wall / floor_wall:.2f}x | "
            f"{rss:.1f} MiB | {rss / floor_rss:.2f}x |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
