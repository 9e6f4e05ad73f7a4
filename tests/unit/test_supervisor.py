"""The supervisor restarts a failing thread with backoff, counts it, and gives up after
too many failures in a short time; a finite worker that returns is done."""

from __future__ import annotations

import logging
import threading

import pytest

from phytrace_edge.runtime.supervisor import Supervisor, Worker
from tests.processes import wait_for


def fast_supervisor(**kwargs: float) -> Supervisor:
    return Supervisor(backoff_min_s=0.01, backoff_max_s=0.02, **kwargs)  # type: ignore[arg-type]


def test_a_failing_worker_is_restarted_and_its_traceback_logged_once_per_failure(
    caplog: pytest.LogCaptureFixture,
) -> None:
    runs: list[int] = []
    done = threading.Event()

    def flaky(stop, beat) -> None:
        runs.append(1)
        if len(runs) <= 2:
            raise RuntimeError(f"boom {len(runs)}")
        beat()
        done.set()
        stop.wait()  # the worker's own event, handed to its loop

    supervisor = fast_supervisor()
    supervisor.start(Worker("flaky", flaky))
    try:
        wait_for(done.is_set, 10, "the third run")
    finally:
        assert supervisor.stop("flaky", 5)
    assert supervisor.restarts["flaky"] == 2 and not supervisor.failed.is_set()
    failures = [r for r in caplog.records if r.levelno == logging.ERROR]
    assert len(failures) == 2 and all(r.exc_info for r in failures)
    assert "boom 1" in str(failures[0].exc_info[1])


def test_too_many_failures_in_the_window_give_up_with_the_reason() -> None:
    def broken(stop, beat) -> None:
        raise ValueError("queue unreadable")

    supervisor = fast_supervisor(max_restarts=3, window_s=60)
    supervisor.start(Worker("sender", broken))
    assert supervisor.failed.wait(10)
    assert supervisor.restarts["sender"] == 3
    assert supervisor.failed_worker == "sender"
    assert "sender failed 3 times" in str(supervisor.failure)
    assert "ValueError: queue unreadable" in str(supervisor.failure)


def test_a_finite_worker_that_returns_is_done_and_not_restarted() -> None:
    calls: list[int] = []
    supervisor = fast_supervisor()
    worker = supervisor.start(Worker("ingest", lambda stop, beat: calls.append(1), finite=True))
    assert worker.done.wait(5)
    assert calls == [1] and supervisor.restarts["ingest"] == 0
    assert "ingest" not in supervisor.progress_ages()


def test_progress_ages_tell_a_stuck_worker_from_a_busy_one() -> None:
    now = [100.0]
    supervisor = Supervisor(monotonic=lambda: now[0])
    release = threading.Event()
    beating = threading.Event()

    def busy(stop, beat) -> None:
        while not release.wait(0.01):
            beat()
            beating.set()

    def stuck(stop, beat) -> None:
        release.wait()

    supervisor.start(Worker("busy", busy))
    supervisor.start(Worker("stuck", stuck))
    try:
        assert beating.wait(5)
        now[0] += 40.0
        beating.clear()
        assert beating.wait(5)
        ages = supervisor.progress_ages()
        assert ages["busy"] == 0.0 and ages["stuck"] == 40.0
    finally:
        release.set()
        supervisor.stop("busy", 5)
        supervisor.stop("stuck", 5)
