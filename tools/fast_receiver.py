"""A minimal fast PhyCloud receiver for benchmarks: what the bridge's drain could reach
against a server that does nothing but read the batch.

    .venv/bin/python tools/fast_receiver.py [--port 0] [--delay-ms 50]

uvicorn + starlette: decompresses the body (gzip, zstd or none), parses it with orjson,
counts the events and their distinct ids, and answers the contract's document
(docs/phycloud-api.md). ``--delay-ms`` adds a server-side wait per request, the round
trip of a cellular link. The first line printed names the bound address.
"""

from __future__ import annotations

import argparse
import asyncio
import gzip
import sys
from pathlib import Path

import orjson
import uvicorn
import zstandard
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import Response
from starlette.routing import Route

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from phytrace_edge.stub.server import bind


def create_app(delay_s: float) -> Starlette:
    seen: set[str] = set()
    received = [0]

    async def events(request: Request) -> Response:
        body = await request.body()
        encoding = request.headers.get("content-encoding", "")
        if encoding == "gzip":
            body = gzip.decompress(body)
        elif encoding == "zstd":
            body = zstandard.ZstdDecompressor().decompress(body)
        batch = orjson.loads(body)["events"]
        before = len(seen)
        seen.update(event["event_id"] for event in batch)
        received[0] += len(batch)
        if delay_s:
            await asyncio.sleep(delay_s)
        new = len(seen) - before
        answer = {"accepted": new, "duplicates": len(batch) - new, "rejected": []}
        return Response(orjson.dumps(answer), media_type="application/json")

    async def counts(request: Request) -> Response:
        return Response(orjson.dumps({"received": received[0], "unique": len(seen)}))

    return Starlette(
        routes=[
            Route("/api/v1/events", events, methods=["POST"]),
            Route("/counts", counts),
        ]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--delay-ms", type=float, default=0.0)
    args = parser.parse_args()
    sock = bind("127.0.0.1", args.port)
    print(f"listening on http://127.0.0.1:{sock.getsockname()[1]}", flush=True)
    config = uvicorn.Config(create_app(args.delay_ms / 1000), log_level="warning", access_log=False)
    uvicorn.Server(config).run(sockets=[sock])


if __name__ == "__main__":
    main()
