"""The PhyCloud dev stub as an ASGI app (Starlette), implementing docs/phycloud-openapi.yaml.

POST /api/v1/events checks the API key, decodes gzip/zstd, validates every event
against the UDM schema, stores new events (deduplicated by event_id) and answers
with counts. Fault injection (latency, errors, Retry-After, dropped connections)
applies to POST /api/v1/events only.

GET /api/v1/incidents and GET /api/v1/incidents/{id} are the live page's view of
``incident`` events (UDM 1.3.0), put together from their parts; like GET /api/v1/robots
they are the stub's own, not PhyCloud's (``x-stub-only`` in docs/phycloud-openapi.yaml).
``/`` and ``/healthz`` are the stub's too, and not in the document.
"""

from __future__ import annotations

import asyncio
import hmac
import logging
import random
import zlib
from importlib import resources
from typing import Any

import orjson
import zstandard
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, Response
from starlette.routing import Route

from phytrace_edge.stub.board import Board
from phytrace_edge.stub.faults import Faults, decide
from phytrace_edge.stub.store import IncidentTooLarge, StubStore
from phytrace_edge.stub.validate import find_violation

log = logging.getLogger(__name__)

MAX_BODY_BYTES = 10 * 1024 * 1024
MAX_DECODED_BYTES = 64 * 1024 * 1024
MAX_EVENTS = 10_000
MAX_INCIDENTS = 1000  # in one answer of GET /api/v1/incidents
MAX_TOPICS = 256  # named in one GET /api/v1/incidents/{id} (as many as an incident holds)


class DroppedConnection(Exception):
    """Raised after the response started, so the server closes the connection mid-answer."""


class DroppedResponse(Response):
    """Starts a 200 answer and breaks off: the client sees the connection drop after the
    batch was stored, as when a response is lost on a flaky link."""

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        await send(
            {
                "type": "http.response.start",
                "status": 200,
                "headers": [(b"content-length", b"4096")],
            }
        )
        raise DroppedConnection


class BodyError(Exception):
    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


def _json(status: int, body: dict[str, Any], headers: dict[str, str] | None = None) -> Response:
    return Response(
        orjson.dumps(body), status_code=status, headers=headers, media_type="application/json"
    )


def _decode(body: bytes, encoding: str) -> bytes:
    """The request body without its Content-Encoding, bounded against zip bombs."""
    encoding = encoding.strip().lower()
    try:
        if encoding in ("", "identity"):
            return body
        if encoding == "gzip":
            inflater = zlib.decompressobj(wbits=31)
            data = inflater.decompress(body, MAX_DECODED_BYTES)
            if inflater.unconsumed_tail:
                raise BodyError(413, "decoded body over 64 MiB")
            return data
        if encoding == "zstd":
            reader = zstandard.ZstdDecompressor().stream_reader(body)
            data = reader.read(MAX_DECODED_BYTES + 1)
            if len(data) > MAX_DECODED_BYTES:
                raise BodyError(413, "decoded body over 64 MiB")
            return data
    except (zlib.error, zstandard.ZstdError) as exc:
        raise BodyError(400, f"body is not valid {encoding}: {exc}") from None
    raise BodyError(415, f"unsupported Content-Encoding {encoding!r} (use gzip, zstd or identity)")


def _events_of(data: bytes) -> list[Any]:
    try:
        document = orjson.loads(data)
    except orjson.JSONDecodeError as exc:
        raise BodyError(400, f"body is not JSON: {exc}") from None
    events = document.get("events") if isinstance(document, dict) else None
    if not isinstance(events, list) or not events:
        raise BodyError(400, 'body must be {"events": [ ... ]} with at least one event')
    if len(events) > MAX_EVENTS:
        raise BodyError(413, f"more than {MAX_EVENTS} events in one request")
    return events


class Stub:
    """State of one stub server: its store, faults, live board and API key."""

    def __init__(self, store: StubStore, faults: Faults, api_key: str | None, seed: int | None):
        self.store = store
        self.faults = faults
        self.api_key = api_key or None
        self.board = Board()
        self.rng = random.Random(seed)

    def authorized(self, request: Request) -> bool:
        if self.api_key is None:
            return True
        given = request.headers.get("authorization", "")
        return hmac.compare_digest(given.encode(), f"Bearer {self.api_key}".encode())

    async def post_events(self, request: Request) -> Response:
        faults = self.faults
        if faults.latency_s:
            await asyncio.sleep(faults.latency_s)
        decision = decide(faults, self.rng)
        if decision.status is not None:
            headers = {"Retry-After": faults.retry_after} if faults.retry_after else None
            return _json(decision.status, {"error": f"injected {decision.status}"}, headers)
        if not self.authorized(request):
            return _json(401, {"error": "missing or unknown API key"})
        body = await request.body()
        if len(body) > MAX_BODY_BYTES:
            return _json(413, {"error": f"body over {MAX_BODY_BYTES} bytes"})
        try:
            events = _events_of(_decode(body, request.headers.get("content-encoding", "")))
        except BodyError as exc:
            return _json(exc.status, {"error": str(exc)})

        rejected = []
        for index, event in enumerate(events):
            violation = find_violation(event)
            if violation is None:
                continue
            event_id = event.get("event_id") if isinstance(event, dict) else None
            detail = {"index": index, "event_id": event_id if isinstance(event_id, str) else None}
            if not faults.partial_rejects:
                self.store.count_rejected(1)
                return _json(
                    400,
                    {
                        "error": "invalid event",
                        **detail,
                        "path": violation.path,
                        "message": str(violation),
                    },
                )
            rejected.append({**detail, "reason": str(violation)})
        valid = [e for i, e in enumerate(events) if i not in {r["index"] for r in rejected}]
        stored, duplicates = self.store.record(valid) if valid else (0, 0)
        if rejected:
            self.store.count_rejected(len(rejected))
        self.board.add(valid)
        if decision.drop:
            return DroppedResponse()
        return _json(200, {"accepted": stored, "duplicates": duplicates, "rejected": rejected})

    async def get_events(self, request: Request) -> Response:
        try:
            after = int(request.query_params.get("after", 0))
            limit = int(request.query_params.get("limit", 1000))
            if after < 0 or not 1 <= limit <= MAX_EVENTS:
                raise ValueError
        except ValueError:
            return _json(400, {"error": "after must be >= 0 and limit from 1 to 10000"})
        events, next_after = self.store.events(request.query_params.get("source_id"), after, limit)
        return _json(200, {"events": events, "next_after": next_after})

    async def get_stats(self, request: Request) -> Response:
        return _json(200, self.store.stats())

    async def get_robots(self, request: Request) -> Response:
        return _json(200, {"robots": self.board.summary()})

    async def get_incidents(self, request: Request) -> Response:
        """The newest incidents first, each with its trigger, window, parts received
        and missing, and sample counts by topic."""
        try:
            limit = int(request.query_params.get("limit", 50))
            if not 1 <= limit <= MAX_INCIDENTS:
                raise ValueError
        except ValueError:
            return _json(400, {"error": f"limit must be from 1 to {MAX_INCIDENTS}"})
        incidents = self.store.incidents(request.query_params.get("source_id"), limit)
        return _json(200, {"incidents": incidents})

    async def get_incident(self, request: Request) -> Response:
        """One incident with ``samples``: its received parts' samples joined per topic,
        in time order; ``?topic=/odom&topic=/imu/data`` for some topics only."""
        incident_id = request.path_params["incident_id"]
        topics = request.query_params.getlist("topic")
        if len(topics) > MAX_TOPICS:
            return _json(400, {"error": f"more than {MAX_TOPICS} topics asked for"})
        try:
            incident = self.store.incident(incident_id, topics)
        except IncidentTooLarge as exc:
            return _json(413, {"error": f"{exc}: ask for fewer topics (?topic=/odom)"})
        if incident is None:
            return _json(404, {"error": f"no incident {incident_id!r}"})
        return _json(200, incident)

    async def get_faults(self, request: Request) -> Response:
        return _json(200, self.faults.as_dict())

    async def put_faults(self, request: Request) -> Response:
        try:
            changes = orjson.loads(await request.body())
            if not isinstance(changes, dict):
                raise ValueError("body must be a JSON object")
            self.faults = self.faults.updated(changes)
        except (ValueError, TypeError) as exc:
            return _json(400, {"error": str(exc)})
        log.info("faults now %s", self.faults.as_dict())
        return _json(200, self.faults.as_dict())

    async def page(self, request: Request) -> Response:
        html = resources.files("phytrace_edge.stub").joinpath("page.html").read_text("utf-8")
        return HTMLResponse(html)

    async def health(self, request: Request) -> Response:
        return JSONResponse({"status": "ok"})


def create_app(stub: Stub) -> Starlette:
    return Starlette(
        routes=[
            Route("/", stub.page),
            Route("/healthz", stub.health),
            Route("/api/v1/events", stub.post_events, methods=["POST"]),
            Route("/api/v1/events", stub.get_events, methods=["GET"]),
            Route("/api/v1/stats", stub.get_stats),
            Route("/api/v1/robots", stub.get_robots),
            Route("/api/v1/incidents", stub.get_incidents),
            Route("/api/v1/incidents/{incident_id}", stub.get_incident),
            Route("/api/v1/faults", stub.get_faults, methods=["GET"]),
            Route("/api/v1/faults", stub.put_faults, methods=["PUT"]),
        ],
    )
