"""A correlation session through the balancer of docker/loopback.sh.

Usage: loopback_session.py LB_URL API_KEY PID_TO_KILL REPLICA1_URL REPLICA2_URL [VICTIM]

Two radars (b reports 1 s after a, scans every 2 s, six targets) stream
their track reports into one session in sequenced batches through nginx;
both replicas serve batches (their /metrics say so), the process PID_TO_KILL
(VICTIM: `replica 1` by default; docker/loopback_sentinel.sh kills the Redis
primary) is killed (SIGKILL) halfway, the session finishes (a batch answered
502/503/504 is retried with the same sequence number, as docs/sessions.md
tells clients to, for up to 60 s), and its decisions equal the batch
endpoint's. Prints the time from the kill to the first accepted batch and
the answers refused meanwhile. Exits non-zero on any difference.
"""

import json
import os
import signal
import sys
import time
import urllib.error
import urllib.request

LB, KEY, PID, R1, R2 = sys.argv[1:6]
VICTIM = sys.argv[6] if len(sys.argv) > 6 else "replica 1"


def call(method, url, body=None, auth=True):
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method=method)
    req.add_header("content-type", "application/json")
    if auth:
        req.add_header("authorization", f"Bearer {KEY}")
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            raw = r.read()
            if "json" in (r.headers.get("content-type") or ""):
                return r.status, json.loads(raw or b"null")
            return r.status, raw.decode(errors="replace")
    except urllib.error.HTTPError as e:
        return e.code, e.read().decode(errors="replace")


def scenario():
    nodes, reports = [], []
    for node, offset, wobble in (("a", 0.0, 0.0), ("b", 1.0, 15.0)):
        tracks = []
        for target in range(6):
            x0, y0, vx, vy = (target * 5000.0, 7000.0 + target * 900.0, 30.0 + 10 * target, -60.0)
            samples = []
            for scan in range(30):
                t = scan * 2.0 + offset
                e = wobble * (((scan * 7 + target) % 5) - 2.0) / 2.0
                s = {"t": t, "state": [x0 + vx * t + e, vx, y0 + vy * t - e, vy],
                     "covariance": [[400.0, 0, 0, 0], [0, 25.0, 0, 0], [0, 0, 400.0, 0], [0, 0, 0, 25.0]]}
                samples.append(s)
                reports.append(dict(s, node=node, track=f"{node}{target}"))
            tracks.append({"id": f"{node}{target}", "samples": samples})
        nodes.append({"id": node, "tracks": tracks})
    reports.sort(key=lambda r: r["t"])
    config = {"state_layout": ["x", "vx", "y", "vy"],
              "method": {"kind": "independent_double_threshold", "rule": {"l": 3, "r": 4}},
              "motion_model": {"process_noise": "dwna", "sigma_a_mps2": 1.0},
              # Fixed grid: the session's instants are the batch call's
              # whatever the batching (docs/sessions.md).
              "alignment": {"period_s": 2.0, "max_staleness_s": 3.0}}
    return dict(config, nodes=nodes), dict(config, kind="correlation", nodes=["a", "b"],
                                           history_instants=1024), reports


def batches_served(url):
    """POST /v1/sessions/{id}/batches answered by one replica (its /metrics)."""
    _, text = call("GET", url + "/metrics")
    total = 0.0
    for line in str(text).splitlines():
        if line.startswith("http_requests_total{") and 'route="/v1/sessions/{id}/batches"' in line:
            total += float(line.rsplit(" ", 1)[1])
    return total


batch, session, reports = scenario()
status, expected = call("POST", LB + "/v1/correlation/tracks", batch)
assert status == 200, (status, expected)
status, created = call("POST", LB + "/v1/sessions", session)
assert status == 201, (status, created)
sid = created["id"]
chunks = [reports[i:i + 12] for i in range(0, len(reports), 12)]
bodies = [{"sequence": i + 1, "reports": c} for i, c in enumerate(chunks)]
bodies.append({"sequence": len(bodies) + 1, "flush": True})
retries = 0
refused = {}
killed_at = kill_time = recovered = None
for i, body in enumerate(bodies):
    if i == len(bodies) // 2:
        served = (batches_served(R1), batches_served(R2))
        print(f"before the kill, batches served: replica 1 {served[0]:.0f}, replica 2 {served[1]:.0f}")
        assert served[0] > 0 and served[1] > 0, "the balancer must use both replicas"
        os.kill(int(PID), signal.SIGKILL)
        killed_at, kill_time = i, time.monotonic()
    deadline = time.monotonic() + 60
    while True:
        status, update = call("POST", f"{LB}/v1/sessions/{sid}/batches", body)
        if status == 200:
            if kill_time is not None and recovered is None:
                recovered = time.monotonic() - kill_time
            break
        # 502/503/504: outcome unknown; the same sequence number is safe.
        assert status in (502, 503, 504), (status, update)
        assert time.monotonic() < deadline, ("no accepted batch within 60 s", status, update)
        refused[status] = refused.get(status, 0) + 1
        retries += 1
        time.sleep(0.1)
status, state = call("GET", f"{LB}/v1/sessions/{sid}")
assert status == 200, (status, state)
# Exactly once: every batch applied, none twice (a retried duplicate is
# acknowledged, not applied again).
assert state["last_sequence"] == len(bodies) == state["batches"], (state["last_sequence"], state["batches"])
print(f"{VICTIM} killed before batch {killed_at + 1} of {len(bodies)}; "
      f"{retries} answer(s) refused ({refused}), each batch retried with its sequence number; "
      f"first batch accepted {recovered:.2f} s after the kill")
same = state["pairs"] == expected["pairs"] and state["system_tracks"] == expected["system_tracks"]
decided = sum(p["decision"] == "correlated" for p in expected["pairs"])
print(f"session decisions equal the batch call's: {same} ({decided} pairs correlated)")
if not same or decided < 6:
    sys.exit(1)
