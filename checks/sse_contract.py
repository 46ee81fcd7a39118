#!/usr/bin/env python3
"""The events stream against its contract: every event of a real stream
(`snapshot`, `update`, `end`) validates against the OpenAPI document's
`itemSchema` for `text/event-stream`, with each `data` checked against its
`contentSchema`; a stream with a wrong `data` must fail (the check bites).

    sse_contract.py BASE_URL [API_KEY]

Run by checks/schemathesis.sh against the server it started (a generated
request rarely finds a live session whose stream ends, so the 200 answer
is exercised here). Needs schemathesis and requests (its venv has both).
"""

import json
import sys
import threading
import time
from pathlib import Path

import requests
import schemathesis

ROOT = Path(__file__).resolve().parent.parent


def main(base: str, key: str | None) -> int:
    headers = {"Authorization": f"Bearer {key}"} if key else {}
    example = lambda name: json.loads((ROOT / "openapi" / "examples" / name).read_text())
    created = requests.post(f"{base}/v1/sessions", json=example("sessions_create.json"), headers=headers)
    created.raise_for_status()
    sid = created.json()["id"]
    box = {}

    def watch():
        box["r"] = requests.get(f"{base}/v1/sessions/{sid}/events", headers=headers, timeout=30)

    watcher = threading.Thread(target=watch)
    watcher.start()
    time.sleep(0.5)
    pushed = requests.post(
        f"{base}/v1/sessions/{sid}/batches", json=example("sessions_batch.json"), headers=headers
    )
    pushed.raise_for_status()
    time.sleep(0.5)
    requests.delete(f"{base}/v1/sessions/{sid}", headers=headers).raise_for_status()
    watcher.join()
    stream = box["r"]
    events = [line[len("event: "):] for line in stream.text.splitlines() if line.startswith("event: ")]
    print(f"events stream: {stream.status_code}, events {events}")
    if events[:1] != ["snapshot"] or events[-1:] != ["end"]:
        print("FAIL: the stream is not snapshot … end")
        return 1
    if "update" not in events:
        print("note: the pushed batch brought no update event (only snapshot and end are checked)")
    schema = schemathesis.openapi.from_url(f"{base}/openapi.json", headers=headers)
    operation = schema["/v1/sessions/{id}/events"]["GET"]
    try:
        operation.validate_response(stream)
    except (Exception, BaseExceptionGroup) as e:  # schemathesis raises a failure group
        print(f"FAIL: the stream violates the document:\n{e}")
        return 1
    broken = requests.models.Response()
    broken.status_code = 200
    broken.headers["Content-Type"] = "text/event-stream"
    broken._content = b'event: update\nid: 3\ndata: {"not": "a BatchUpdate"}\n\n'
    broken.request, broken.url = stream.request, stream.url
    try:
        operation.validate_response(broken)
    except (Exception, BaseExceptionGroup):
        print("SSE contract: every event validates; a wrong data is caught")
        return 0
    print("FAIL: a wrong event passed the document's itemSchema")
    return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else None))
