"""One ``phytrace-edge run`` per queue *file*, whatever path names it, and one owners
folder for every process on it (issue 31, item 9): real processes, each spelling of
the queue's path. A second ``run`` through any of them stops within seconds with one
line naming the first one's pid and path while the first goes on; a ``drain`` through
a symlink beside the service takes back none of its live claims."""

from __future__ import annotations

import os
import re
import signal
import stat
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from phytrace_edge.queue.peek import read_stats
from tests.processes import BridgeProcess, free_port, python_env, status_json, wait_for

TOOK_BACK = "took back the claims"
REFUSED_WITHIN_S = 20  # a start of the interpreter and the imports, on a slow CI machine


def started(log: Path) -> bool:
    return log.exists() and "input sim" in log.read_text()


def start_first(tmp_path: Path, queue: Path, log: str = "first", **env: str) -> BridgeProcess:
    """``run`` on ``queue``, sending to PhyCloud at ``env``'s endpoint, or to a port of
    127.0.0.1 nobody listens on; started once it says so in its log."""
    env.setdefault("PHYCLOUD_ENDPOINT", f"http://127.0.0.1:{free_port()}/api/v1")
    first = BridgeProcess(tmp_path / f"{log}.log", QUEUE_PATH=str(queue), BRIDGE_INPUT="sim", **env)
    first.start()
    try:
        wait_for(lambda: started(first.log), 30, f"the {log} run to start")
    except BaseException:
        first.stop()
        raise
    return first


def run_second(spelling: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """A second ``phytrace-edge run`` with QUEUE_PATH spelled so, from ``cwd``; killed
    (and the test failed) if it is not refused within REFUSED_WITHIN_S."""
    endpoint = f"http://127.0.0.1:{free_port()}/api/v1"
    env = python_env(QUEUE_PATH=spelling, BRIDGE_INPUT="sim", PHYCLOUD_ENDPOINT=endpoint)
    command = [sys.executable, "-m", "phytrace_edge", "run", "--input", "sim"]
    with subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=cwd, env=env
    ) as second:
        try:
            out, err = second.communicate(timeout=REFUSED_WITHIN_S)
        except subprocess.TimeoutExpired:
            os.kill(second.pid, signal.SIGKILL)
            second.communicate()
            pytest.fail(f"a second run through {spelling} was not refused: both ran")
    return subprocess.CompletedProcess(command, second.returncode, out, err)


def one_line(result: subprocess.CompletedProcess[str]) -> str:
    lines = result.stderr.strip().splitlines()
    assert "Traceback" not in result.stderr and len(lines) == 1, result.stderr
    return lines[0]


def bind_mount(source: Path, target: Path) -> Callable[[], None]:
    """``mount --bind source target``; the unmount to call at the end."""
    if os.geteuid() != 0:
        pytest.skip("a bind mount needs root (CI runs as root)")
    target.mkdir()
    done = subprocess.run(["mount", "--bind", str(source), str(target)], capture_output=True)
    if done.returncode:
        pytest.skip(f"cannot bind-mount here: {done.stderr.decode().strip()}")
    return lambda: subprocess.run(["umount", "-l", str(target)], check=False)


# each: (the spelling of the queue's path for the second run, the folder it runs in)
Spell = Callable[[Path, Path], tuple[str, Path]]


def same_path(tmp: Path, queue: Path) -> tuple[str, Path]:
    return str(queue), tmp


def relative(tmp: Path, queue: Path) -> tuple[str, Path]:
    return "queue.db", queue.parent


def dotted(tmp: Path, queue: Path) -> tuple[str, Path]:
    return "./data/../data/queue.db", tmp


def symlink_to_file(tmp: Path, queue: Path) -> tuple[str, Path]:
    (queue.parent / "alias.db").symlink_to("queue.db")
    return str(queue.parent / "alias.db"), tmp


def symlink_to_folder(tmp: Path, queue: Path) -> tuple[str, Path]:
    (tmp / "linked").symlink_to(queue.parent, target_is_directory=True)
    return str(tmp / "linked" / "queue.db"), tmp


def hard_link(tmp: Path, queue: Path) -> tuple[str, Path]:
    os.link(queue, queue.parent / "alias.db")
    return str(queue.parent / "alias.db"), tmp


def hard_link_elsewhere(tmp: Path, queue: Path) -> tuple[str, Path]:
    (tmp / "elsewhere").mkdir()
    os.link(queue, tmp / "elsewhere" / "other.db")
    return str(tmp / "elsewhere" / "other.db"), tmp


SPELLINGS: dict[str, Spell] = {
    "same path": same_path,
    "relative": relative,
    "dotted": dotted,
    "symlink to the file": symlink_to_file,
    "symlink to the folder": symlink_to_folder,
    "hard link": hard_link,
    "hard link in another folder": hard_link_elsewhere,
}


@pytest.fixture
def queue(tmp_path: Path) -> Iterator[Path]:
    """Where the first run puts its queue: a folder that does not exist yet."""
    yield tmp_path / "data" / "queue.db"


def assert_refused(
    second: subprocess.CompletedProcess[str], first: BridgeProcess, path: Path
) -> None:
    assert first.process is not None
    assert second.returncode == 4, second.stderr
    line = one_line(second)
    assert f"in use by another phytrace-edge run (pid {first.process.pid}) through {path}" in line
    assert first.process.poll() is None, "the first run stopped"


@pytest.mark.parametrize("spelling", SPELLINGS)
def test_a_second_run_through_any_name_of_the_queue_file_is_refused(
    tmp_path: Path, queue: Path, spelling: str
) -> None:
    first = start_first(tmp_path, queue)  # a first start: no folder, no file yet
    try:
        assert stat.S_IMODE(queue.parent.stat().st_mode) == 0o700
        name, cwd = SPELLINGS[spelling](tmp_path, queue)
        second = run_second(name, cwd)
        assert_refused(second, first, queue)
        pid = first.process.pid  # and the first is still at work, on its queue

        def first_at_work() -> bool:
            return status_json(QUEUE_PATH=str(queue))[1].get("service", {}).get("pid") == pid

        wait_for(first_at_work, 30, "the first run's heartbeat")
    finally:
        first.stop()


def test_a_second_run_through_a_bind_mount_of_the_folder_is_refused(
    tmp_path: Path, queue: Path
) -> None:
    queue.parent.mkdir(mode=0o700)
    unmount = bind_mount(queue.parent, tmp_path / "mounted")
    try:
        first = start_first(tmp_path, queue)
        try:
            second = run_second(str(tmp_path / "mounted" / "queue.db"), tmp_path)
            assert_refused(second, first, queue)
        finally:
            first.stop()
    finally:
        unmount()


@pytest.mark.parametrize("spelling", ["symlink to the file", "hard link"])
def test_the_first_run_through_another_name_refuses_the_real_path(
    tmp_path: Path, queue: Path, spelling: str
) -> None:
    """The other way round: the first runs through the alias, the second through the
    file's own path, and is told the alias."""
    queue.parent.mkdir(mode=0o700)
    queue.touch(mode=0o600)
    name, cwd = SPELLINGS[spelling](tmp_path, queue)
    first = start_first(tmp_path, Path(name))
    try:
        second = run_second(str(queue), cwd)
        assert_refused(second, first, Path(name))
    finally:
        first.stop()


def test_the_lock_of_a_killed_run_never_blocks_the_next(tmp_path: Path, queue: Path) -> None:
    first = start_first(tmp_path, queue)
    first.signal(signal.SIGKILL)  # no chance to clean up: its lock file stays
    first.wait(10)
    assert Path(f"{queue}.lock").exists()
    (tmp_path / "alias.db").symlink_to(queue)
    following = start_first(tmp_path, tmp_path / "alias.db", "following")  # another name
    following.stop()


def test_a_drain_through_a_symlink_takes_back_no_live_claims(
    tmp_path: Path, queue: Path, stub
) -> None:
    """The service's claims and a drain's, both live, on one queue named two ways: each
    finds the other's owner alive (one owners folder), so neither takes back anything.
    PhyCloud answers slowly, so that claims stay open while sends are under way."""
    stub.set_faults(latency_s=2.0)
    env = {
        "PHYCLOUD_ENDPOINT": stub.endpoint,
        "SAMPLE_RATE_HZ": "50",
        "BATCH_SIZE": "10",
        "FLUSH_INTERVAL_S": "0.2",
        "RETRY_MIN_S": "0.05",
        "RETRY_MAX_S": "0.5",
    }
    first = start_first(tmp_path, queue, **env)
    try:
        (tmp_path / "linked").symlink_to(queue.parent, target_is_directory=True)
        alias = tmp_path / "linked" / "alias.db"
        alias.symlink_to(queue)  # a symlink to the file, in a symlinked folder

        def leased() -> bool:
            stats = read_stats(str(queue))
            return stats is not None and stats.leased > 0

        wait_for(leased, 60, "the service's claim of a batch")
        drain = subprocess.run(
            [sys.executable, "-m", "phytrace_edge", "drain", "--timeout", "4"],
            capture_output=True,
            text=True,
            timeout=60,
            env=python_env(QUEUE_PATH=str(alias), **env),
        )
        assert "in use" not in drain.stderr  # drain beside the service stays allowed
        sent = re.match(r"(?:drained|sent) (\d+) event", drain.stdout)
        assert sent and int(sent.group(1)) > 0, (drain.stdout, drain.stderr)
        assert TOOK_BACK not in drain.stderr
        assert first.process is not None and first.process.poll() is None
        assert TOOK_BACK not in first.log.read_text()
        assert not Path(f"{alias}.owners").exists()  # one owners folder, the file's own
        assert Path(f"{queue}.owners").is_dir()
    finally:
        first.stop()
