"""The tracker relay /ws/tracker (persival/deploy/tracker_relay.py): a publisher's messages reach
every subscriber as sent, subscribers learn when a publisher comes and goes, and what would hurt
the server (binary, oversized, too fast, too many) is refused without closing anything else."""

from __future__ import annotations

import json

import pytest
from fastapi import FastAPI, WebSocketDisconnect
from fastapi.testclient import TestClient

from persival.deploy.tracker_relay import TrackerRelay, add_tracker_relay


@pytest.fixture()
def relay_client():
    app = FastAPI()
    relay = add_tracker_relay(app, TrackerRelay(max_bytes=256, rate=50.0, burst=10.0, max_publishers=1))
    with TestClient(app) as client:
        yield client, relay


def _next_data(ws) -> dict:
    """The next message that is not a status line."""
    while True:
        message = json.loads(ws.receive_text())
        if message.get("type") != "status":
            return message


def test_messages_reach_every_subscriber_as_sent(relay_client):
    client, relay = relay_client
    with client.websocket_connect("/ws/tracker") as a, client.websocket_connect("/ws/tracker?role=subscribe") as b:
        assert json.loads(a.receive_text()) == {"type": "status", "publishers": 0}
        assert json.loads(b.receive_text()) == {"type": "status", "publishers": 0}
        with client.websocket_connect("/ws/tracker?role=publish") as pub:
            assert json.loads(a.receive_text()) == {"type": "status", "publishers": 1}
            sent = [{"t": 1.0 + k / 60, "elbow_deg": 10.0 * k} for k in range(5)]
            for s in sent:
                pub.send_text(json.dumps(s))
            assert [_next_data(a) for _ in sent] == sent
            assert [_next_data(b) for _ in sent] == sent
            pub.send_text("not json at all")  # the relay does not judge content: the page does
            assert a.receive_text() == "not json at all"
        assert json.loads(a.receive_text()) == {"type": "status", "publishers": 0}  # the tracker left
    assert relay.publishers == 0 and not relay.subscribers


def test_what_would_hurt_the_server_is_refused_and_the_publisher_stays(relay_client):
    client, _ = relay_client
    with client.websocket_connect("/ws/tracker?role=publish") as pub:
        pub.send_bytes(b"\x00\x01")
        assert json.loads(pub.receive_text())["status"] == 422
        pub.send_text("x" * 300)
        assert json.loads(pub.receive_text())["status"] == 413
        for _ in range(30):  # burst of 10 at 50/s: the rest is refused
            pub.send_text("{}")
        assert json.loads(pub.receive_text())["status"] == 429
        with pytest.raises(WebSocketDisconnect) as full, client.websocket_connect("/ws/tracker?role=publish") as second:
            second.receive_text()  # one publisher at most here
        assert full.value.code == 1013
    with pytest.raises(WebSocketDisconnect) as bad, client.websocket_connect("/ws/tracker?role=admin") as ws:
        ws.receive_text()
    assert bad.value.code == 1008

