"""Stream an elbow movement into the viewer as a motion tracker would (docs/viewer.md, "Live").

A tracker publishes one JSON message per sample on the server's relay, ``/ws/tracker?role=publish``;
every page showing the viewer with its live source on "tracker" follows it. Two kinds of message:

    {"t": 1765112345.016, "elbow_deg": 87.5}
    {"t": 1765112345.016, "upper_arm": [w, x, y, z], "forearm": [w, x, y, z]}

(``t``: the tracker's clock in seconds, optional; the quaternions: each segment's orientation, the
sensor strapped with its x axis along the bone; an optional ``"axis": [x, y, z]`` names another.)

    python docs/examples/tracker_client.py [OUT]                      # self-check, no server needed
    python docs/examples/tracker_client.py --url ws://127.0.0.1:8000/ws/tracker --lo 0 --hi 120 --period 2
    python docs/examples/tracker_client.py --url ws://127.0.0.1:8000/ws/tracker --quaternions --cycles 5

Without ``--url`` the relay runs in this process (the same code as ``persival serve``, under
FastAPI's test client): the movement goes through it as angles and as quaternions, and the
script prints how many messages came through and how far the angle between the two segments'
axes (the page's formula, here in Python) lies from the angle that was sent. With ``--url`` it
streams the movement in real time to a running ``persival serve``: a cosine from ``--lo`` up
to ``--hi`` and back, ``--period`` seconds per cycle, at ``--rate`` samples a second.
"""

import argparse
import json
import math
import sys
import time


def quat_mul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return [aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw]


def about(axis, deg):
    s, c = math.sin(math.radians(deg) / 2), math.cos(math.radians(deg) / 2)
    return [c, *(s * v for v in axis)]


def rotate(q, v):
    w, x, y, z = q
    conj = [w, -x, -y, -z]
    return quat_mul(quat_mul(q, [0.0, *v]), conj)[1:]


def segments(elbow_deg, twist_deg=0.0):
    """Upper arm hanging (sensor x axis pointing down), forearm flexed about the elbow's hinge
    (y) and twisted about its own axis by ``twist_deg`` (pronation: no part of the elbow angle)."""
    upper = about([0.0, 1.0, 0.0], 90.0)  # x -> -z: along the hanging upper arm
    fore = quat_mul(quat_mul(upper, about([0.0, 1.0, 0.0], -elbow_deg)), about([1.0, 0.0, 0.0], twist_deg))
    return upper, fore


def axis_angle(upper, fore, axis=(1.0, 0.0, 0.0)):
    """The elbow angle from two orientations: the angle between the segments' axes (as the page)."""
    u, f = rotate(upper, axis), rotate(fore, axis)
    cos = sum(a * b for a, b in zip(u, f)) / math.sqrt(sum(a * a for a in u) * sum(b * b for b in f))
    return math.degrees(math.acos(max(-1.0, min(1.0, cos))))


def movement(lo, hi, period, cycles, rate):
    """(t, angle) of a cosine from lo up to hi and back, `cycles` times."""
    n = int(round(period * cycles * rate))
    return [(k / rate, lo + (hi - lo) * 0.5 * (1 - math.cos(2 * math.pi * k / (rate * period)))) for k in range(n + 1)]


def message(t, angle, quaternions, k):
    if not quaternions:
        return {"t": t, "elbow_deg": round(angle, 4)}
    upper, fore = segments(angle, twist_deg=30.0 * math.sin(0.05 * k))
    return {"t": t, "upper_arm": [round(v, 7) for v in upper], "forearm": [round(v, 7) for v in fore]}


def stream(url, samples, quaternions):
    """Send the samples in real time (each at its own time after the first)."""
    from websockets.sync.client import connect

    with connect(url + ("&" if "?" in url else "?") + "role=publish") as ws:
        start = time.time()
        for k, (t, angle) in enumerate(samples):
            delay = start + t - time.time()
            if delay > 0:
                time.sleep(delay)
            ws.send(json.dumps(message(start + t, angle, quaternions, k)))
        time.sleep(0.2)  # let the last messages leave before closing
    print(f"sent: {len(samples)} samples in {time.time() - start:.2f} s")


def self_check(samples):
    from fastapi import FastAPI
    from fastapi.testclient import TestClient

    from persival.deploy.tracker_relay import TrackerRelay, add_tracker_relay

    app = FastAPI()
    add_tracker_relay(app, TrackerRelay(rate=1e6, burst=1e6))  # no pacing here: the test client sends at once
    received, worst = 0, 0.0
    with TestClient(app) as client, client.websocket_connect("/ws/tracker") as page:
        with client.websocket_connect("/ws/tracker?role=publish") as tracker:
            for quaternions in (False, True):
                for k, (t, angle) in enumerate(samples):
                    tracker.send_text(json.dumps(message(t, angle, quaternions, k)))
                    got = json.loads(page.receive_text())
                    while got.get("type") == "status":
                        got = json.loads(page.receive_text())
                    received += 1
                    if quaternions:
                        worst = max(worst, abs(axis_angle(got["upper_arm"], got["forearm"]) - angle))
    print(f"relayed: {received} of {2 * len(samples)} messages")
    print(f"largest quaternion angle error: {worst:.2e} deg")


def main(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", help="output folder (unused: nothing is written)")
    parser.add_argument("--url", help="the relay of a running persival serve, e.g. ws://127.0.0.1:8000/ws/tracker")
    parser.add_argument("--lo", type=float, default=0.0)
    parser.add_argument("--hi", type=float, default=120.0)
    parser.add_argument("--period", type=float, default=2.0, help="seconds per cycle")
    parser.add_argument("--cycles", type=int, default=1)
    parser.add_argument("--rate", type=float, default=60.0, help="samples per second")
    parser.add_argument("--quaternions", action="store_true", help="send segment orientations, not angles")
    args = parser.parse_args(argv)
    samples = movement(args.lo, args.hi, args.period, args.cycles, args.rate)
    if args.url:
        stream(args.url, samples, args.quaternions)
    else:
        self_check(samples)


if __name__ == "__main__":
    main(sys.argv[1:])
