"""The tracker relay: ``/ws/tracker``, where a motion tracker publishes elbow data and pages subscribe.

A tracker (an IMU app, a motion-capture bridge, docs/examples/tracker_client.py) connects with
``?role=publish`` and sends one JSON text message per sample; every page connected with
``?role=subscribe`` (the default) receives each message as it was sent. The message format is
the page's business (docs/viewer.md, "Live"): the relay checks only what keeps the server safe,

- text messages of at most ``max_bytes`` (a binary or larger one is answered with an error and
  dropped), at most ``rate`` messages per second per publisher (with a burst);
- at most ``max_publishers`` publishers and ``max_subscribers`` subscribers at once;
- a subscriber that falls behind (its queue full) loses the oldest messages, never the server
  its memory: live data is only worth its newest sample.

Subscribers also get ``{"type": "status", "publishers": n}`` when a publisher comes or goes, so
a page can say "the tracker disconnected" at once instead of waiting for silence.
"""

from __future__ import annotations

import asyncio
import contextlib
import json

from fastapi import FastAPI, WebSocket, WebSocketDisconnect

from persival.deploy.protocol import TokenBucket

__all__ = ["TrackerRelay", "add_tracker_relay"]

_QUEUE = 64  # messages per subscriber, newest kept


class TrackerRelay:
    """Fan-out of publishers' text messages to subscribers (one asyncio loop, no locks needed)."""

    def __init__(self, max_bytes: int = 4096, rate: float = 250.0, burst: float = 60.0,
                 max_publishers: int = 4, max_subscribers: int = 32) -> None:
        self.max_bytes, self.rate, self.burst = max_bytes, rate, burst
        self.max_publishers, self.max_subscribers = max_publishers, max_subscribers
        self.publishers = 0
        self.subscribers: set[asyncio.Queue] = set()
        self.relayed = 0

    def broadcast(self, text: str) -> None:
        for queue in self.subscribers:
            if queue.full():  # a slow page: drop its oldest message, keep the newest
                queue.get_nowait()
            queue.put_nowait(text)
        self.relayed += 1

    def status(self) -> None:
        self.broadcast(json.dumps({"type": "status", "publishers": self.publishers}))

    async def publish(self, ws: WebSocket) -> None:
        bucket = TokenBucket(self.rate, self.burst)
        self.publishers += 1
        self.status()
        try:
            while True:
                message = await ws.receive()
                if message["type"] == "websocket.disconnect":
                    return
                text = message.get("text")
                if text is None:
                    status, error = 422, "binary messages are not relayed: send JSON text"
                elif len(text.encode()) > self.max_bytes:
                    status, error = 413, f"message larger than {self.max_bytes} bytes"
                elif not bucket.take():
                    status, error = 429, f"more than {self.rate:g} messages/s: slow down"
                else:
                    self.broadcast(text)
                    continue
                await ws.send_json({"error": error, "status": status})
        finally:
            self.publishers -= 1
            self.status()

    async def subscribe(self, ws: WebSocket) -> None:
        queue: asyncio.Queue = asyncio.Queue(_QUEUE)
        self.subscribers.add(queue)
        queue.put_nowait(json.dumps({"type": "status", "publishers": self.publishers}))

        async def drain_incoming() -> None:  # a subscriber only listens; its close ends the loop
            while (await ws.receive())["type"] != "websocket.disconnect":
                pass

        listener = asyncio.create_task(drain_incoming())
        try:
            while not listener.done():
                getter = asyncio.create_task(queue.get())
                done, _ = await asyncio.wait({getter, listener}, return_when=asyncio.FIRST_COMPLETED)
                if getter in done:
                    await ws.send_text(getter.result())
                else:
                    getter.cancel()
        finally:
            self.subscribers.discard(queue)
            listener.cancel()
            with contextlib.suppress(asyncio.CancelledError, WebSocketDisconnect, RuntimeError):
                await listener


def add_tracker_relay(app: FastAPI, relay: TrackerRelay | None = None) -> TrackerRelay:
    """Mount ``/ws/tracker`` on the app; returns the relay (its counters are the tests')."""
    relay = relay or TrackerRelay()
    app.state.tracker_relay = relay

    @app.websocket("/ws/tracker")
    async def tracker(ws: WebSocket, role: str = "subscribe") -> None:
        if role not in ("publish", "subscribe"):
            await ws.close(code=1008, reason="role must be publish or subscribe")
            return
        full = relay.publishers >= relay.max_publishers if role == "publish" else \
            len(relay.subscribers) >= relay.max_subscribers
        if full:
            await ws.close(code=1013, reason="too many publishers" if role == "publish" else "too many subscribers")
            return
        await ws.accept()
        with contextlib.suppress(WebSocketDisconnect, asyncio.CancelledError):
            await (relay.publish(ws) if role == "publish" else relay.subscribe(ws))

    return relay
