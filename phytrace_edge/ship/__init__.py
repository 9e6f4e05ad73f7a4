"""Ship: the queue -> PhyCloud over HTTP, in batches, with retries that never drop data.

``request`` builds a batch's body and headers, ``responses`` says what an answer
means, ``transport`` is the only HTTP code, ``throttle`` caps upload bandwidth and
``sender`` runs the loop.
"""

from phytrace_edge.ship.sender import Sender, SendPolicy, SendStats
from phytrace_edge.ship.transport import FunctionTransport, HttpTransport, Transport

__all__ = ["FunctionTransport", "HttpTransport", "SendPolicy", "SendStats", "Sender", "Transport"]
