"""Supervised threads: every long-running loop of the service (ingest, sampler, writer,
sender, heartbeat, maintenance) runs under a ``Supervisor``.

A loop that raises is logged once with its traceback, counted (``restarts``) and
restarted after a backoff that doubles up to ``backoff_max_s``. A loop that fails
``max_restarts`` times within ``window_s`` cannot be kept alive: the supervisor sets
``failed`` with the reason, and the process exits non-zero so that systemd or Docker
restarts it. Each loop calls ``beat()`` as it makes progress; ``progress_ages`` says how
long ago each last did, so ``status`` can name a stage that is stuck.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

log = logging.getLogger(__name__)

Beat = Callable[[], None]
DEFAULT_MAX_RESTARTS = 5
DEFAULT_WINDOW_S = 60.0
DEFAULT_BACKOFF_MIN_S = 0.5
DEFAULT_BACKOFF_MAX_S = 30.0


Loop = Callable[[threading.Event, Beat], None]


@dataclass
class Worker:
    """A named loop: ``run(stop, beat)`` until ``stop`` is set, which only
    ``Supervisor.stop`` does: every loop stops the same way. A loop whose owner also
    waits on a stop event of its own (the writer's hand-off, the sender's backoff)
    lends that event here. A ``finite`` loop may also return on its own when its work
    is done (a replayed bag)."""

    name: str
    run: Loop
    stop: threading.Event = field(default_factory=threading.Event)
    finite: bool = False
    done: threading.Event = field(default_factory=threading.Event)
    thread: threading.Thread | None = None


class Supervisor:
    """Starts, restarts and stops workers; see the module doc."""

    def __init__(
        self,
        *,
        max_restarts: int = DEFAULT_MAX_RESTARTS,
        window_s: float = DEFAULT_WINDOW_S,
        backoff_min_s: float = DEFAULT_BACKOFF_MIN_S,
        backoff_max_s: float = DEFAULT_BACKOFF_MAX_S,
        monotonic: Callable[[], float] = time.monotonic,
    ) -> None:
        self.max_restarts = max_restarts
        self.window_s = window_s
        self.backoff_min_s = backoff_min_s
        self.backoff_max_s = backoff_max_s
        self._monotonic = monotonic
        self.workers: dict[str, Worker] = {}
        self.restarts: Counter[str] = Counter()
        self.failed = threading.Event()
        self.failure: str | None = None
        self.failed_worker: str | None = None
        self._beats: dict[str, float] = {}
        self._lock = threading.Lock()

    def start(self, worker: Worker) -> Worker:
        self.workers[worker.name] = worker
        self._beat(worker.name)
        worker.thread = threading.Thread(
            target=self._supervise, args=(worker,), name=worker.name, daemon=True
        )
        worker.thread.start()
        return worker

    def stop(self, name: str, timeout_s: float) -> bool:
        """Ask one worker to stop and wait for it; False if it did not within the time."""
        worker = self.workers.get(name)
        if worker is None or worker.thread is None:
            return True
        worker.stop.set()
        worker.thread.join(timeout_s)
        return not worker.thread.is_alive()

    def progress_ages(self) -> dict[str, float]:
        """Seconds since each running worker last made progress."""
        now = self._monotonic()
        with self._lock:
            return {
                name: round(now - at, 1)
                for name, at in self._beats.items()
                if not self.workers[name].done.is_set()
            }

    def _beat(self, name: str) -> None:
        with self._lock:
            self._beats[name] = self._monotonic()

    def _supervise(self, worker: Worker) -> None:
        backoff = self.backoff_min_s
        failures: deque[float] = deque()
        while not worker.stop.is_set():
            started = self._monotonic()
            try:
                worker.run(worker.stop, lambda: self._beat(worker.name))
            except Exception as exc:
                now = self._monotonic()
                if now - started > self.window_s:
                    backoff = self.backoff_min_s  # it had been healthy for a while
                failures.append(now)
                while failures and failures[0] < now - self.window_s:
                    failures.popleft()
                self.restarts[worker.name] += 1
                if len(failures) >= self.max_restarts:
                    self.failure = (
                        f"thread {worker.name} failed {len(failures)} times in "
                        f"{self.window_s:.0f} s, last: {type(exc).__name__}: {exc}"
                    )
                    log.critical("%s; giving up", self.failure, exc_info=True)
                    self.failed_worker = worker.name
                    self.failed.set()
                    break
                log.error(
                    "thread %s failed; restarting it in %.1f s", worker.name, backoff, exc_info=True
                )
                if worker.stop.wait(backoff):
                    break
                backoff = min(2 * backoff, self.backoff_max_s)
            else:
                if worker.finite or worker.stop.is_set():
                    break
                log.warning("thread %s returned unasked; restarting it", worker.name)
                if worker.stop.wait(backoff):
                    break
        worker.done.set()
