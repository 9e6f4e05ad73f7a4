"""Ship: the queue -> PhyCloud over HTTP, in batches, with retries that never drop data.

``options`` holds the send policy, ``request`` builds a batch's body and headers,
``responses`` says what an answer means, ``transport`` is the only HTTP code,
``throttle`` caps upload bandwidth, ``retries`` says when to try again and
``sender`` runs the loop.
"""
