"""When, and how loudly, the sender tries a batch again. There is no attempt limit:
retries never drop data (docs/phycloud-api.md, "What each answer does").

The wait before the next try is ``Retry-After`` when the server gave one, never sooner
than RETRY_MIN_S (a 0, a negative value or a date in the past would make a tight
loop) and up to 20% later, so a fleet told the same time spreads out; RETRY_MAX_S for
refusals data cannot fix, and for a single event whose answers never account for it;
else exponential backoff with full jitter, which spreads a fleet's retries after an
outage: try ``n`` (from 1) waits a uniform draw between RETRY_MIN_S and
min(RETRY_MAX_S, RETRY_MIN_S * 2 ** (n - 1)). Every draw is the sender's ``rng``'s,
so a seeded one makes the waits reproducible.
"""

from __future__ import annotations

import logging
import random

from tenacity import RetryCallState, wait_exponential

from phytrace_edge.errors import EndpointRefusedError, TransientSendError, UnaccountedAnswerError
from phytrace_edge.ship.options import SendPolicy

log = logging.getLogger(__name__)

RETRY_AFTER_JITTER = 0.2  # up to 20% later than asked, so a fleet told the same time spreads
# answers in a row that do not account for a batch before it is halved: one may be a
# glitch; a batch that always gets them may hold an event PhyCloud miscounts
UNACCOUNTED_BEFORE_SPLIT = 3


class Backoff:
    """The wait before the next try of a batch."""

    def __init__(self, policy: SendPolicy, rng: random.Random) -> None:
        self._min_s, self._max_s = policy.retry_min_s, policy.retry_max_s
        self._rng = rng
        # the exponential bound of the full jitter (never below RETRY_MIN_S: no tight
        # loop); tenacity's wait_random_exponential would draw from the global random
        self._bound = wait_exponential(multiplier=self._min_s, max=self._max_s, min=self._min_s)

    def seconds(self, state: RetryCallState, long: bool = False) -> float:
        """Seconds to wait after the failed try ``state`` holds; RETRY_MAX_S when
        ``long``."""
        exc = state.outcome.exception() if state.outcome else None
        if isinstance(exc, EndpointRefusedError) or long:
            return self._max_s
        if isinstance(exc, TransientSendError) and exc.retry_after is not None:
            wait = max(exc.retry_after, self._min_s)
            return wait * (1 + RETRY_AFTER_JITTER * self._rng.random())
        return self._rng.uniform(self._min_s, self._bound(state))


def say_retrying(exc: BaseException | None, attempt: int, wait_s: float) -> None:
    """Log a failed try: each refusal (ERROR: a person must act) and each answer that
    did not add up (PhyCloud is wrong), other failures at the first try and every
    tenth (an outage would fill the journal)."""
    if isinstance(exc, EndpointRefusedError):
        log.error("%s; keeping the queued events, retrying in %.0f s", exc, wait_s)
    elif isinstance(exc, UnaccountedAnswerError):
        log.warning("%s, retrying in %.1f s", exc, wait_s)
    elif attempt == 1 or attempt % 10 == 0:
        log.warning("send failed (%s), attempt %d; retrying in %.1f s", exc, attempt, wait_s)


def say_halving(exc: UnaccountedAnswerError, events: int) -> None:
    log.warning(
        "%s; %d answers in a row did not add up: sending the %d events in halves",
        exc,
        UNACCOUNTED_BEFORE_SPLIT,
        events,
    )
