#!/usr/bin/env python3
"""Every probe of issue 53 ("Hostile clients and failing parts") against a
release binary, stdlib Python only; one table at the end: probe, figure,
pass or fail against the issue's expectation.

Each probe group starts its own server (the binary, on free loopback ports)
with the default configuration, plus only the settings the probe needs,
printed with its rows:

  memory     120 connections each POST a 16 kB gzip body inflating to
             15.9 MiB, sent but for its last 8 bytes and held; the server's
             peak resident memory (VmHWM). `--h2`: the same bombs as 120
             streams of one HTTP/2 connection. Expectation: under 600 MiB.
  asterix    the ASTERIX UDP listener (--asterix-udp, a spec of one 2D radar
             with 1-s scans): 10 good scans of one aircraft, one CAT048
             datagram whose time of day is 6 h ahead, 12 good scans; the
             good plots after it must all be accepted (none late) and the
             track must keep updating. The same run with the clock check
             off (FUSION_ASTERIX_MAX_CLOCK_OFFSET_S=0) shows the failure the
             issue found. And a listener with FUSION_ASTERIX_ALLOW=10.0.0.0/8
             must refuse every datagram from 127.0.0.1.
  amplify    a 200 kB radar id, 300 plots naming an unknown radar among 64
             radars of 64-byte ids, and a history over its bound: small 4xx
             answers naming the field.
  watchers   2,000 watches of random session ids: each a 404, nothing held
             (watchers gauge, RSS).
  tracks     an aircraft over a radar site in a session (one scan a batch):
             every batch applies, the warning names the track; a session at
             FUSION_MAX_TRACKS_PER_SESSION=3 with 6 aircraft: every batch
             applies and says it refused new tracks.
  tenancy    with API keys (FUSION_API_KEYS) and the Redis store
             (FUSION_SESSION_STORE=redis://127.0.0.1:6379/0): /metrics
             without a key is a 401; /healthz/store and /readyz name no
             host; a gRPC session call without a key fails closed
             (UNAUTHENTICATED); the /view/ page's CSP.
  quota      the memory store with two tenants and
             FUSION_SESSION_MEMORY_BYTES_PER_TENANT=1048576: one tenant fills
             its share (a 429 naming the limit), the other is still served.
  budgets    exact JPDA over its edge budget (a 24 × 24 cluster): answered,
             the cluster falls back, the server's peak memory barely moves;
             2 × 1,001 co-located correlation tracks: a 422 naming `nodes`;
             a long JPDA update under FUSION_REQUEST_TIMEOUT_S=1 and
             FUSION_MAX_IN_FLIGHT=1: a 504, then the slot is free again (the
             time until a small request is served).

Usage: checks/hostile_probes.py [--binary PATH] [--probes a,b,...]
                                [--connections N] [--h2]
The binary defaults to $CARGO_TARGET_DIR/release/radar-fusion (target/ when
unset); build it first with `cargo build --release --bin radar-fusion`.
Extra server settings go in the environment (FUSION_*), as for the server.
Exit status 0 when every probe passes.
"""

import argparse
import base64
import gzip
import http.client
import json
import math
import os
import random
import socket
import struct
import subprocess
import sys
import threading
import time

INFLATED = 16 * 1024 * 1024 - 64 * 1024  # 15.94 MiB: under FUSION_MAX_BODY_BYTES
PATH = "/v1/correlation/rules/evaluate"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def status_kib(pid, field):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise RuntimeError(f"no {field} for pid {pid}")


def bomb():
    head = b'{"alpha": 0.05, '
    tail = b'"rules": [{"l": 1, "r": 1}]}'
    body = head + b" " * (INFLATED - len(head) - len(tail)) + tail
    return gzip.compress(body, compresslevel=9)


def wait_until_serving(port, proc, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            sys.exit(f"the server exited with {proc.returncode}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1) as s:
                s.sendall(b"GET /readyz HTTP/1.1\r\nHost: probe\r\nConnection: close\r\n\r\n")
                if s.recv(64).startswith(b"HTTP/1.1 200"):
                    return
        except OSError:
            pass
        time.sleep(0.1)
    sys.exit("the server did not become ready")


def answered(sock):
    """The status line the server sent on `sock` so far, or None."""
    sock.setblocking(False)
    try:
        data = sock.recv(4096)
    except BlockingIOError:
        return None
    except OSError as e:
        return f"reset ({e.__class__.__name__})"
    if not data:
        return "closed"
    return data.split(b"\r\n", 1)[0].decode(errors="replace")


class H2Bombs:
    """One HTTP/2 connection (prior knowledge) that opens `streams` POSTs
    of `body` and holds each without its last 8 bytes, within the
    connection's flow-control window (a reader thread follows the server's
    WINDOW_UPDATEs)."""

    def __init__(self, port, streams, body):
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.lock = threading.Condition()
        self.window = 65_535
        self.max_streams = None
        self.answered = 0
        self.refused = 0
        self.closed = False
        self.sock.sendall(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + frame(4, 0, 0, b""))
        threading.Thread(target=self.read, daemon=True).start()
        with self.lock:
            self.lock.wait_for(lambda: self.max_streams is not None or self.closed, timeout=10)
        for k in range(streams):
            sid = 2 * k + 1
            self.sock.sendall(frame(1, 4, sid, hpack_post(len(body))))  # END_HEADERS
            data = body[:-8]
            for at in range(0, len(data), 16_384):
                chunk = data[at:at + 16_384]
                with self.lock:
                    if not self.lock.wait_for(
                        lambda: self.window >= len(chunk) or self.closed, timeout=10
                    ) or self.closed:
                        return
                    self.window -= len(chunk)
                self.sock.sendall(frame(0, 0, sid, chunk))

    def read(self):
        buf = b""
        try:
            while True:
                data = self.sock.recv(65_536)
                if not data:
                    break
                buf += data
                while len(buf) >= 9:
                    length = int.from_bytes(buf[:3], "big")
                    if len(buf) < 9 + length:
                        break
                    kind, flags = buf[3], buf[4]
                    sid = int.from_bytes(buf[5:9], "big") & 0x7FFF_FFFF
                    payload, buf = buf[9:9 + length], buf[9 + length:]
                    with self.lock:
                        if kind == 4 and not flags & 1:  # SETTINGS
                            settings = {}
                            for i in range(0, len(payload), 6):
                                key, value = struct.unpack(">HI", payload[i:i + 6])
                                settings[key] = value
                            self.max_streams = settings.get(3, self.max_streams or "none")
                            self.sock.sendall(frame(4, 1, 0, b""))  # ACK
                        elif kind == 8 and sid == 0:  # WINDOW_UPDATE
                            self.window += int.from_bytes(payload, "big") & 0x7FFF_FFFF
                        elif kind == 1:  # HEADERS: a response
                            self.answered += 1
                        elif kind == 3:  # RST_STREAM
                            self.refused += 1
                        elif kind == 7:  # GOAWAY
                            break
                        self.lock.notify_all()
        except OSError:
            pass
        with self.lock:
            self.closed = True
            self.lock.notify_all()


def frame(kind, flags, sid, payload):
    return len(payload).to_bytes(3, "big") + bytes([kind, flags]) + sid.to_bytes(4, "big") + payload


def hpack_post(length):
    """The request's header block: literal fields without indexing (RFC 7541 §6.2.2),
    no Huffman coding."""
    def field(name, value):
        return b"\x00" + bytes([len(name)]) + name + bytes([len(value)]) + value
    return b"".join([
        field(b":method", b"POST"),
        field(b":scheme", b"http"),
        field(b":path", PATH.encode()),
        field(b":authority", b"probe"),
        field(b"content-type", b"application/json"),
        field(b"content-encoding", b"gzip"),
        field(b"content-length", str(length).encode()),
    ])



# ---------------------------------------------------------------- the server


class Server:
    """The binary on free loopback ports with `settings` (FUSION_* names)
    over the caller's environment; stopped on exit."""

    def __init__(self, binary, settings=None, label="defaults"):
        self.binary = binary
        self.settings = dict(settings or {})
        self.label = label
        self.http_port, self.grpc_port = free_port(), free_port()

    def __enter__(self):
        env = dict(os.environ)
        env.update({
            "FUSION_HTTP_ADDR": f"127.0.0.1:{self.http_port}",
            "FUSION_GRPC_ADDR": f"127.0.0.1:{self.grpc_port}",
            "FUSION_LOG": env.get("FUSION_LOG", "warn"),
        })
        env.update(self.settings)
        self.proc = subprocess.Popen([self.binary], env=env, stdout=subprocess.DEVNULL)
        wait_until_serving(self.http_port, self.proc)
        self.conn = None
        return self

    def __exit__(self, *exc):
        if self.conn is not None:
            self.conn.close()
        self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()

    def kib(self, field):
        return status_kib(self.proc.pid, field)

    def request(self, method, path, body=None, headers=None, timeout=120):
        """(status, headers, body bytes, seconds) of one request on a kept-alive
        connection (reopened when the server closed it)."""
        data = None
        hdrs = dict(headers or {})
        if body is not None:
            data = body if isinstance(body, bytes) else json.dumps(body).encode()
            hdrs.setdefault("content-type", "application/json")
        for attempt in range(2):
            if self.conn is None:
                self.conn = http.client.HTTPConnection("127.0.0.1", self.http_port, timeout=timeout)
            start = time.monotonic()
            try:
                self.conn.request(method, path, body=data, headers=hdrs)
                r = self.conn.getresponse()
                payload = r.read()
            except (http.client.HTTPException, OSError):
                self.conn.close()
                self.conn = None
                if attempt:
                    raise
                continue
            took = time.monotonic() - start
            if r.getheader("connection", "").lower() == "close":
                self.conn.close()
                self.conn = None
            return r.status, {k.lower(): v for k, v in r.getheaders()}, payload, took
        raise RuntimeError("unreachable")

    def json(self, method, path, body=None, headers=None, expect=None):
        status, _, payload, _ = self.request(method, path, body, headers)
        out = json.loads(payload) if payload else None
        if expect is not None and status != expect:
            raise RuntimeError(f"{method} {path}: {status} {payload[:500]!r}")
        return status, out

    def metric(self, name, headers=None):
        """The sum of every sample of `name` in /metrics (0 when absent)."""
        _, _, text, _ = self.request("GET", "/metrics", headers=headers)
        total = 0.0
        for line in text.decode().splitlines():
            if line.startswith(name) and line[len(name):len(name) + 1] in (" ", "{"):
                total += float(line.rsplit(" ", 1)[1])
        return total


class Table:
    def __init__(self):
        self.rows = []

    def add(self, probe, figure, ok, expectation):
        self.rows.append((probe, figure, ok, expectation))
        print(f"  [{'pass' if ok else 'FAIL'}] {probe}: {figure} (expected: {expectation})",
              flush=True)

    def print(self):
        print()
        print("| probe | figure | expected (issue 53) | result |")
        print("|---|---|---|---|")
        for probe, figure, ok, expectation in self.rows:
            print(f"| {probe} | {figure} | {expectation} | {'pass' if ok else 'FAIL'} |")
        failed = sum(1 for r in self.rows if not r[2])
        print(f"\n{len(self.rows) - failed} passed, {failed} failed")
        return failed


def section(title, settings):
    extra = ", ".join(f"{k}={v}" for k, v in settings.items()) or "default configuration"
    print(f"\n== {title} ({extra})", flush=True)


# ---------------------------------------------------------------- memory


def probe_memory(args, table, h2):
    section("memory before admission" + (", HTTP/2" if h2 else ", HTTP/1.1"), {})
    with Server(args.binary) as srv:
        rss_idle = srv.kib("VmRSS")
        body = bomb()
        head = (
            f"POST {PATH} HTTP/1.1\r\nHost: probe\r\nContent-Type: application/json\r\n"
            f"Content-Encoding: gzip\r\nContent-Length: {len(body)}\r\n\r\n"
        ).encode()
        socks, holder, thread = [], [], None
        if h2:
            thread = threading.Thread(target=lambda: holder.append(
                H2Bombs(srv.http_port, args.connections, body)), daemon=True)
            thread.start()
        else:
            for _ in range(args.connections):
                s = socket.create_connection(("127.0.0.1", srv.http_port))
                s.sendall(head + body[:-8])
                socks.append(s)
        deadline = time.monotonic() + args.hold_s
        while time.monotonic() < deadline:
            time.sleep(0.1)
        hwm = srv.kib("VmHWM")
        outcomes = {}
        for s in socks:
            line = answered(s) or "held (no answer yet)"
            outcomes[line] = outcomes.get(line, 0) + 1
        for s in socks:
            s.close()
        if thread is not None:
            thread.join(timeout=1)
            bombs = holder[0] if holder else None
            if bombs is not None:
                with bombs.lock:
                    outcomes["HTTP/2 streams answered (503 or other)"] = bombs.answered
                    outcomes["HTTP/2 streams reset by the server"] = bombs.refused
                    outcomes[f"HTTP/2 streams announced: {bombs.max_streams}"] = 1
                bombs.sock.close()
    print(f"  {args.connections} bombs of {len(body)} bytes inflating to "
          f"{INFLATED / 2**20:.2f} MiB, held {args.hold_s:.0f} s; RSS idle "
          f"{rss_idle / 1024:.0f} MiB")
    for line, n in sorted(outcomes.items()):
        print(f"    {n:4d} × {line}")
    what = f"{args.connections} gzip bombs held, " + ("one HTTP/2 connection" if h2 else "HTTP/1.1")
    answers = ", ".join(f"{n} × {line}" for line, n in sorted(outcomes.items())
                        if not line.startswith("HTTP/2 streams announced"))
    table.add(what, f"peak RSS {hwm / 1024:.0f} MiB (idle {rss_idle / 1024:.0f}); {answers}",
              hwm / 1024 < 600, "peak RSS under 600 MiB")


# ---------------------------------------------------------------- ASTERIX

NM_M = 1852.0
LISTENER_SESSION = "00000000000000000000000000000048"


def cat048_block(reports):
    """One CAT048 data block, each report (sac, sic, time of day s, range m,
    azimuth deg) as the 11-byte record of `eval::asterix048`: FSPEC 0xF0,
    I048/010, /140 (1/128 s), /020 (single PSR), /040 (1/256 NM, 2^-16 turn)."""
    records = b""
    for sac, sic, tod, rng, az in reports:
        t = round(tod * 128) % (86_400 * 128)
        rho = round(rng / NM_M * 256)
        theta = round((az % 360.0) / 360.0 * 65_536) % 65_536
        records += bytes([0xF0, sac, sic]) + t.to_bytes(3, "big") + bytes([0x20])
        records += rho.to_bytes(2, "big") + theta.to_bytes(2, "big")
    return bytes([48]) + (3 + len(records)).to_bytes(2, "big") + records


def asterix_run(args, settings, spec, datagrams, want_plots, timeout=30):
    """A server whose listener feeds a session from `spec`, `datagrams`
    (bytes) sent at `args.asterix_pace_s`; returns the session's view and the
    /metrics counters' moves once it counts `want_plots` plots or the
    refused datagrams are all counted (bounded wait)."""
    port = free_udp_port()
    spec_path = f"/tmp/hostile-probe-spec-{os.getpid()}-{port}.json"
    with open(spec_path, "w") as f:
        json.dump(spec, f)
    settings = dict(settings)
    settings.update({"FUSION_ASTERIX_UDP": f"127.0.0.1:{port}",
                     "FUSION_ASTERIX_SESSION_SPEC": spec_path})
    names = ["fusion_asterix_datagrams_total", "fusion_asterix_records_total",
             "fusion_asterix_plots_total", "fusion_asterix_decode_errors_total",
             "fusion_asterix_refused_datagrams_total", "fusion_asterix_late_plots_total"]
    try:
        with Server(args.binary, settings) as srv:
            before = {n: srv.metric(n) for n in names}
            sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            for d in datagrams:
                sender.sendto(d, ("127.0.0.1", port))
                time.sleep(args.asterix_pace_s)
            sender.close()
            deadline = time.monotonic() + timeout
            while True:
                _, view = srv.json("GET", f"/v1/sessions/{LISTENER_SESSION}", expect=200)
                moved = {n: srv.metric(n) - before[n] for n in names}
                seen = moved["fusion_asterix_datagrams_total"] + \
                    moved["fusion_asterix_refused_datagrams_total"]
                plots = view["plot_fusion"]["counters"]["plots"]
                if (plots >= want_plots and seen >= len(datagrams)) or time.monotonic() > deadline:
                    return view, moved
                time.sleep(0.05)
    finally:
        os.remove(spec_path)


def probe_asterix(args, table):
    spec = {"kind": "plot_fusion",
            "radars": [{"id": "a", "kind": "2d", "site": {"position_m": [-20000.0, 0.0]},
                        "sigma_range_m": 60.0, "sigma_azimuth_deg": 0.08,
                        "scan_period_s": 1.0, "sac": 25, "sic": 1}],
            "tracker": {"default_height_m": 3000.0}}
    # One aircraft 30 km east of the radar moving away at 25 m/s (slant
    # range from 3,000 m up), a plot every 1-s scan, the last 1 s before
    # the first datagram is sent: 10 good scans, one 6 h ahead, 12 good.
    now = time.time()
    good_times = [now - 23.0 + k for k in range(22)]

    def good(k):
        ground = 30_000.0 + 25.0 * k
        return cat048_block([(25, 1, good_times[k] % 86_400, math.hypot(ground, 3_000.0), 90.0)])

    ahead = cat048_block([(25, 1, (now + 6 * 3600.0) % 86_400, 32_000.0, 90.0)])
    datagrams = [good(k) for k in range(10)] + [ahead] + [good(k) for k in range(10, 22)]
    last_good_t = good_times[-1]
    for label, offset in (("after", None), ("clock check off", "0")):
        settings = {} if offset is None else {"FUSION_ASTERIX_MAX_CLOCK_OFFSET_S": offset}
        section(f"ASTERIX listener, one datagram 6 h ahead ({label})",
                {**settings, "FUSION_ASTERIX_UDP": "127.0.0.1:<port>",
                 "FUSION_ASTERIX_SESSION_SPEC": "one 2D radar, 1-s scans"})
        view, moved = asterix_run(args, settings, spec, datagrams, 22 if offset is None else 23,
                                  timeout=15)
        c = view["plot_fusion"]["counters"]
        confirmed = [t for t in view["plot_fusion"]["tracks"] if t["status"] == "confirmed"]
        last = max((t["last_update_t"] for t in confirmed), default=float("nan"))
        # The track's last update against the last good plot's time, both
        # as times of day (the session places them on a date).
        off = ((last - last_good_t) + 43_200) % 86_400 - 43_200 if confirmed else float("nan")
        figure = (f"22 good plots + 1 ahead: {c['plots']} accepted, {c['late']} late, "
                  f"{moved['fusion_asterix_decode_errors_total']:.0f} refused; "
                  f"{len(confirmed)} confirmed track, its last update "
                  f"{off:+.2f} s from the last good plot's time")
        if offset is None:
            ok = (c["plots"] == 22 and c["late"] == 0 and len(confirmed) == 1
                  and abs(off) < 0.01)
            table.add("ASTERIX: CAT048 datagram 6 h ahead among 1-s scans", figure, ok,
                      "every good plot after it accepted, none late; the track updates")
        else:
            # Informative: what the issue found, with the check turned off.
            table.add("ASTERIX: the same with FUSION_ASTERIX_MAX_CLOCK_OFFSET_S=0 (the "
                      "failure the check prevents)", figure, c["late"] >= 11,
                      "good plots after it late (the issue's finding)")
    settings = {"FUSION_ASTERIX_ALLOW": "10.0.0.0/8"}
    section("ASTERIX listener, allowlist", settings)
    view, moved = asterix_run(args, settings, spec, datagrams[:10], 0, timeout=3)
    refused = moved["fusion_asterix_refused_datagrams_total"]
    plots = view["plot_fusion"]["counters"]["plots"]
    table.add("ASTERIX: FUSION_ASTERIX_ALLOW=10.0.0.0/8, 10 datagrams from 127.0.0.1",
              f"{refused:.0f} refused, {plots} plots in the session",
              refused == 10 and plots == 0, "every datagram refused, counted")


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ---------------------------------------------------------------- amplification

TRACK = "/v1/plot-fusion/track"


def radar_2d(rid="west", x=0.0, y=0.0, period=4.0):
    return {"id": rid, "kind": "2d", "site": {"position_m": [x, y]},
            "sigma_range_m": 50.0, "sigma_azimuth_deg": 0.05, "scan_period_s": period}


def plots_2d(radar, targets, duration, height, rng, period=4.0):
    """Plots of a 2D radar at the local frame's origin: `targets` as
    (x0, y0, vx, vy) seen every `period` from t = 0 to `duration`."""
    out = []
    for k in range(int(duration / period) + 1):
        t = k * period
        for x0, y0, vx, vy in targets:
            x, y = x0 + vx * t - radar["site"]["position_m"][0], y0 + vy * t - radar["site"]["position_m"][1]
            out.append({"radar_id": radar["id"], "t": t,
                        "range_m": math.sqrt(x * x + y * y + height * height) + rng.gauss(0, 20),
                        "azimuth_deg": math.degrees(math.atan2(x, y)) + rng.gauss(0, 0.02)})
    return out


def plot_request(n_targets=3, duration=40.0):
    rng = random.Random(53)
    radar = radar_2d()
    targets = [(-30_000.0 + 5_000.0 * i, 40_000.0, 200.0, 0.0) for i in range(n_targets)]
    return {"radars": [radar], "plots": plots_2d(radar, targets, duration, 8_000.0, rng),
            "tracker": {"default_height_m": 8_000.0}}


def probe_amplify(args, table):
    section("response amplification", {})
    with Server(args.binary) as srv:
        req = plot_request()
        status, _, body, took = srv.request("POST", TRACK, req)
        base_ok = status == 200
        req["radars"][0]["id"] = "r" * 200_000
        sent = len(json.dumps(req))
        status, _, body, took = srv.request("POST", TRACK, req)
        fields = [e["field"] for e in json.loads(body).get("errors", [])] if body else []
        table.add("a 200 kB radar id",
                  f"{status}, {len(body):,} bytes answering {sent:,} (fields {fields})",
                  base_ok and status == 422 and len(body) < 1_000 and fields == ["radars[0].id"],
                  "a small 4xx naming the field (before: 20 MB)")

        # 64 radars of 64-byte ids, 300 plots naming a radar that is not one.
        req = plot_request()
        template = req["radars"][0]
        req["radars"] = [dict(template, id=f"{i:064d}") for i in range(64)]
        req["plots"] = [dict(p, radar_id="nowhere") for p in (req["plots"] * 300)[:300]]
        sent = len(json.dumps(req))
        status, _, body, took = srv.request("POST", TRACK, req)
        errors = json.loads(body).get("errors", []) if body else []
        table.add("300 plots naming an unknown radar, 64 radars of 64-byte ids",
                  f"{status}, {len(body):,} bytes, {len(errors)} violations listed",
                  status == 422 and len(body) < 20_000 and len(errors) == 101,
                  "the ids listed once, violations capped (100 + a count)")

        # A history over its bound: 60 aircraft 4 km apart under one 2D
        # radar with 1-s scans, each plot at its own time (every plot is a
        # frame): about 1,800 frames of about 60 confirmed tracks, some
        # 90,000 track states, over the bound of 50,000.
        rng = random.Random(7)
        radar = radar_2d(period=1.0)
        targets = [(-60_000.0 + 4_000.0 * (i % 10), 40_000.0 + 4_000.0 * (i // 10), 200.0, 0.0)
                   for i in range(60)]
        plots = plots_2d(radar, targets, 30.0, 8_000.0, rng, period=1.0)
        last, k = None, 0
        for p in plots:
            k = k + 1 if p["t"] == last else 0
            last = p["t"]
            p["t"] = p["t"] + k * 1e-3
        req = {"radars": [radar], "plots": plots, "tracker": {"default_height_m": 8_000.0},
               "history": True}
        sent = len(json.dumps(req))
        status, _, body, took = srv.request("POST", TRACK, req)
        problem = json.loads(body) if body else {}
        fields = [e["field"] for e in problem.get("errors", [])]
        message = problem.get("errors", [{}])[0].get("message", "")
        table.add("plot-fusion history over its bound (1,800 frames × 60 tracks)",
                  f"{status} in {took:.2f} s, {len(body):,} bytes answering {sent:,}; "
                  f"fields {fields}: \"{message[:90]}\"",
                  status == 422 and fields == ["history"] and len(body) < 2_000,
                  "a clear error naming the bound, not gigabytes")


# ---------------------------------------------------------------- watchers


def probe_watchers(args, table, n=2000):
    section("watchers of sessions that do not exist", {})
    with Server(args.binary) as srv:
        srv.request("GET", f"/v1/sessions/{'0' * 32}/events")  # warm the path
        rss0 = srv.kib("VmRSS")
        statuses = {}
        start = time.monotonic()
        for _ in range(n):
            sid = "%032x" % random.getrandbits(128)
            status, _, _, _ = srv.request("GET", f"/v1/sessions/{sid}/events",
                                          headers={"accept": "text/event-stream"})
            statuses[status] = statuses.get(status, 0) + 1
        took = time.monotonic() - start
        watchers = srv.metric("fusion_session_watchers")
        rss1 = srv.kib("VmRSS")
    figure = (f"{', '.join(f'{v} × {k}' for k, v in sorted(statuses.items()))} in {took:.1f} s; "
              f"watchers gauge {watchers:.0f}; RSS {rss0 / 1024:.1f} → {rss1 / 1024:.1f} MiB")
    table.add(f"{n:,} watches of random session ids", figure,
              statuses == {404: n} and watchers == 0 and rss1 - rss0 < 16 * 1024,
              "each a 404 holding nothing (before: a channel and a subscription for 60 s each)")


# ---------------------------------------------------------------- failing tracks


def overflight_scans():
    """An aircraft flying straight over a 3D radar at 3,000 m, 100 m/s, and
    one 40 m beside it; one scan every 4 s (the REST test's scene)."""
    scans = []
    for k in range(21):
        t = 4.0 * k
        plots = []
        for north in (0.0, 40.0):
            e, n, u = -4_000.0 + 100.0 * t, north, 3_000.0
            horizontal = math.hypot(e, n)
            if horizontal < 1.0:
                continue  # nothing seen overhead
            plots.append({"radar_id": "r", "t": t, "range_m": math.hypot(horizontal, u),
                          "azimuth_deg": math.degrees(math.atan2(e, n)),
                          "elevation_deg": math.degrees(math.atan2(u, horizontal))})
        scans.append(plots)
    return scans


def push_scans(srv, spec, scans):
    """The statuses and warnings of `scans` pushed one a batch into a new
    session of `spec`, the most tracks a batch's answer held, and the
    session's view after the last."""
    _, created = srv.json("POST", "/v1/sessions", spec, expect=201)
    url = f"/v1/sessions/{created['id']}/batches"
    statuses, warnings, most = {}, [], 0
    for i, plots in enumerate(scans):
        status, out = srv.json("POST", url, {"sequence": i + 1, "plots": plots})
        statuses[status] = statuses.get(status, 0) + 1
        if status == 200:
            warnings.extend(out["warnings"])
            most = max(most, len(out["plot_fusion"]["tracks"]))
    _, view = srv.json("GET", f"/v1/sessions/{created['id']}", expect=200)
    return statuses, warnings, most, view


def probe_tracks(args, table):
    section("a track over a radar site, in a session", {})
    spec = {"kind": "plot_fusion",
            "radars": [{"id": "r", "kind": "3d", "site": {"position_m": [0.0, 0.0, 0.0]},
                        "sigma_range_m": 5.0, "sigma_azimuth_deg": 0.0057,
                        "sigma_elevation_deg": 0.0057, "scan_period_s": 4.0,
                        "p_detection": 1.0, "clutter_density": 1e-9}],
            "tracker": {}}
    with Server(args.binary) as srv:
        for motion in ("imm", "cv"):
            s = dict(spec, tracker={} if motion == "imm" else {"motion": "cv", "sigma_a_mps2": 0.05})
            statuses, warnings, _, view = push_scans(srv, s, overflight_scans())
            named = [w for w in warnings if "track" in w and ("site" in w or "associate" in w)]
            confirmed = sum(1 for t in view["plot_fusion"]["tracks"] if t["status"] == "confirmed")
            table.add(f"overflight of a radar site, 21 one-scan batches ({motion})",
                      f"{', '.join(f'{v} × {k}' for k, v in statuses.items())}; "
                      f"{len(named)} warnings naming the track"
                      + (f" (\"{named[0][:80]}…\")" if named else "")
                      + f"; {confirmed} confirmed tracks at the end",
                      statuses == {200: 21} and confirmed == 2,
                      "every batch applies, the session goes on")
    settings = {"FUSION_MAX_TRACKS_PER_SESSION": "3"}
    section("a session at max_tracks", settings)
    rng = random.Random(3)
    radar = radar_2d()
    targets = [(-30_000.0 + 8_000.0 * i, 40_000.0, 200.0, 0.0) for i in range(6)]
    plots = plots_2d(radar, targets, 60.0, 8_000.0, rng)
    scans = [[p for p in plots if p["t"] == 4.0 * k] for k in range(16)]
    with Server(args.binary, settings) as srv:
        statuses, warnings, most, view = push_scans(
            srv, {"kind": "plot_fusion", "radars": [radar], "tracker": {"default_height_m": 8_000.0}},
            scans)
        limit = [w for w in warnings if "limit of 3 tracks" in w]
        live = len(view["plot_fusion"]["tracks"])
        plots_in = view["plot_fusion"]["counters"]["plots"]
    table.add("6 aircraft in a session at FUSION_MAX_TRACKS_PER_SESSION=3 (16 one-scan batches)",
              f"{', '.join(f'{v} × {k}' for k, v in statuses.items())}; {plots_in} plots taken; "
              f"most tracks in a batch's answer {most}; {len(limit)} warnings"
              + (f" (\"{limit[0][:90]}…\")" if limit else "")
              + f"; GET of the session after the last batch: {live} live tracks",
              statuses == {200: 16} and most <= 3 and live <= 3 and len(limit) > 0
              and plots_in == 6 * 16,
              "the batch applies, new tracks refused with a warning, at most 3 tracks")


# ---------------------------------------------------------------- tenancy

ACME = "acme-key-0123456789"
GLOBEX = "globex-key-0123456789"


def probe_tenancy(args, table):
    settings = {"FUSION_API_KEYS": f"{ACME}=acme,{GLOBEX}=globex",
                "FUSION_SESSION_STORE": "redis://127.0.0.1:6379/0",
                "FUSION_SESSION_KEY_PREFIX": f"hostile-probe-{os.getpid()}"}
    section("tenancy and exposure", settings)
    with Server(args.binary, settings) as srv:
        bare, _, _, _ = srv.request("GET", "/metrics")
        keyed, _, _, _ = srv.request("GET", "/metrics", headers={"authorization": f"Bearer {ACME}"})
        table.add("/metrics without a key, API keys on", f"{bare} (with a tenant's key: {keyed})",
                  bare == 401 and keyed == 200, "401")
        leaks = []
        for path in ("/healthz/store", "/readyz"):
            status, _, body, _ = srv.request("GET", path)
            text = body.decode(errors="replace")
            named = [w for w in ("127.0.0.1", "6379", "redis://", "localhost") if w in text]
            leaks.append((path, status, text, named))
        table.add("/healthz/store and /readyz with Redis",
                  "; ".join(f"{p} {s} {t}" for p, s, t, _ in leaks),
                  all(not n for *_, n in leaks), "no host, port or URL")
        for port, name in ((srv.grpc_port, "gRPC port"), (srv.http_port, "REST port")):
            without = grpc_call(port, "/radar.fusion.v1.SessionService/ListSessions", b"")
            keyed = grpc_call(port, "/radar.fusion.v1.SessionService/ListSessions", b"",
                              {"authorization": f"Bearer {ACME}"})
            table.add(f"gRPC SessionService/ListSessions without a key ({name})",
                      f"grpc-status {without[0]} ({GRPC_CODES.get(without[0], '?')}: "
                      f"\"{without[1][:60]}\"); with acme's key: {keyed[0]}",
                      without[0] in (7, 16) and keyed[0] == 0,
                      "fails closed: UNAUTHENTICATED or PERMISSION_DENIED")
        status, headers, _, _ = srv.request("GET", "/view/")
        csp = headers.get("content-security-policy", "")
        table.add("/view/ Content-Security-Policy", f"{status}; \"{csp}\"",
                  status == 200 and "unsafe-inline" not in csp.split("style-src")[0]
                  and "frame-ancestors 'none'" in csp,
                  "scripts without 'unsafe-inline', frame-ancestors 'none'")


GRPC_CODES = {0: "OK", 3: "INVALID_ARGUMENT", 4: "DEADLINE_EXCEEDED", 5: "NOT_FOUND",
              7: "PERMISSION_DENIED", 8: "RESOURCE_EXHAUSTED", 14: "UNAVAILABLE",
              16: "UNAUTHENTICATED"}


def grpc_call(port, path, message, metadata=None, timeout=10):
    """(grpc-status, grpc-message) of one unary gRPC call over HTTP/2 with
    prior knowledge: the request's header block as literals, the answer's
    decoded by `Hpack`."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    try:
        sock.sendall(b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + frame(4, 0, 0, b""))

        def field(name, value):
            return b"\x00" + hpack_int(len(name), 7, 0) + name + hpack_int(len(value), 7, 0) + value
        fields = [(b":method", b"POST"), (b":scheme", b"http"), (b":path", path.encode()),
                  (b":authority", b"probe"), (b"content-type", b"application/grpc"),
                  (b"te", b"trailers")]
        fields += [(k.encode(), v.encode()) for k, v in (metadata or {}).items()]
        sock.sendall(frame(1, 4, 1, b"".join(field(k, v) for k, v in fields)))  # END_HEADERS
        sock.sendall(frame(0, 1, 1, b"\x00" + len(message).to_bytes(4, "big") + message))
        decoder, headers, buf, block = Hpack(), {}, b"", b""
        while True:
            data = sock.recv(65_536)
            if not data:
                break
            buf += data
            while len(buf) >= 9:
                length = int.from_bytes(buf[:3], "big")
                if len(buf) < 9 + length:
                    break
                kind, flags = buf[3], buf[4]
                payload, buf = buf[9:9 + length], buf[9 + length:]
                if kind == 4 and not flags & 1:
                    sock.sendall(frame(4, 1, 0, b""))
                elif kind in (1, 9):  # HEADERS, CONTINUATION
                    if kind == 1 and flags & 8:  # PADDED
                        payload = payload[1:len(payload) - payload[0]]
                    if kind == 1 and flags & 0x20:  # PRIORITY
                        payload = payload[5:]
                    block += payload
                    if flags & 4:  # END_HEADERS
                        headers.update(decoder.decode(block))
                        block = b""
                        if "grpc-status" in headers:
                            return int(headers["grpc-status"]), percent_decode(
                                headers.get("grpc-message", ""))
                elif kind == 7:
                    break
        return -1, "no grpc-status"
    finally:
        sock.close()


def hpack_int(value, prefix, first):
    limit = (1 << prefix) - 1
    if value < limit:
        return bytes([first | value])
    out = [first | limit]
    value -= limit
    while value >= 128:
        out.append(value % 128 + 128)
        value //= 128
    out.append(value)
    return bytes(out)


def percent_decode(text):
    out, i = bytearray(), 0
    raw = text.encode()
    while i < len(raw):
        if raw[i] == 0x25 and i + 2 < len(raw):
            out.append(int(raw[i + 1:i + 3], 16))
            i += 3
        else:
            out.append(raw[i])
            i += 1
    return out.decode(errors="replace")


# RFC 7541 Appendix A: the static table.
STATIC = [
    (":authority", ""), (":method", "GET"), (":method", "POST"), (":path", "/"),
    (":path", "/index.html"), (":scheme", "http"), (":scheme", "https"), (":status", "200"),
    (":status", "204"), (":status", "206"), (":status", "304"), (":status", "400"),
    (":status", "404"), (":status", "500"), ("accept-charset", ""),
    ("accept-encoding", "gzip, deflate"), ("accept-language", ""), ("accept-ranges", ""),
    ("accept", ""), ("access-control-allow-origin", ""), ("age", ""), ("allow", ""),
    ("authorization", ""), ("cache-control", ""), ("content-disposition", ""),
    ("content-encoding", ""), ("content-language", ""), ("content-length", ""),
    ("content-location", ""), ("content-range", ""), ("content-type", ""), ("cookie", ""),
    ("date", ""), ("etag", ""), ("expect", ""), ("expires", ""), ("from", ""), ("host", ""),
    ("if-match", ""), ("if-modified-since", ""), ("if-none-match", ""), ("if-range", ""),
    ("if-unmodified-since", ""), ("last-modified", ""), ("link", ""), ("location", ""),
    ("max-forwards", ""), ("proxy-authenticate", ""), ("proxy-authorization", ""),
    ("range", ""), ("referer", ""), ("refresh", ""), ("retry-after", ""), ("server", ""),
    ("set-cookie", ""), ("strict-transport-security", ""), ("transfer-encoding", ""),
    ("user-agent", ""), ("vary", ""), ("via", ""), ("www-authenticate", ""),
]

# RFC 7541 Appendix B: the Huffman code's length of each symbol 0-255
# ('a' = 5 bits … 'z' = 30 bits); EOS (256) has 30. The code is canonical
# (codes assigned in order of length, then symbol), so the lengths give it.
HUFFMAN_LENGTHS = (
    "isxxxxxxxtzxxzxxxxxxxxzxxxxxxxxxbffhibdgffdgdbbbaaabbbbbbbcdkbhf"
    "ibccccccccccccccccccccccdcdioijbkabababbbaccbbbabcbaabccccckgjix"
    "prpprrrsrssssststtrstssssqrsrsstrqprrssqsrrtqrssqqrqsrssprrrsrrs"
    "vvporsruvvvwwvtuoqvwwvwtqqvvxwwwptpqrqqsrruuttvsvwvvwwwwwxwwwwwv"
)


def huffman_table():
    lengths = [ord(c) - ord("a") + 5 for c in HUFFMAN_LENGTHS] + [30]
    assert len(lengths) == 257, len(lengths)
    table, code, previous = {}, 0, None
    for symbol in sorted(range(257), key=lambda s: (lengths[s], s)):
        if previous is not None:
            code = (code + 1) << (lengths[symbol] - previous)
        previous = lengths[symbol]
        table[(lengths[symbol], code)] = symbol
    return table


class Hpack:
    """An HPACK (RFC 7541) header-block decoder: static and dynamic tables,
    Huffman-coded strings."""

    HUFFMAN = None

    def __init__(self):
        self.dynamic = []
        if Hpack.HUFFMAN is None:
            Hpack.HUFFMAN = huffman_table()

    def entry(self, index):
        if index <= len(STATIC):
            return STATIC[index - 1]
        return self.dynamic[index - len(STATIC) - 1]

    @staticmethod
    def integer(data, pos, prefix):
        value = data[pos] & ((1 << prefix) - 1)
        pos += 1
        if value < (1 << prefix) - 1:
            return value, pos
        shift = 0
        while True:
            b = data[pos]
            pos += 1
            value += (b & 127) << shift
            shift += 7
            if not b & 128:
                return value, pos

    def string(self, data, pos):
        huffman = data[pos] & 0x80
        length, pos = self.integer(data, pos, 7)
        raw = data[pos:pos + length]
        pos += length
        if not huffman:
            return raw.decode(errors="replace"), pos
        out, code, bits = bytearray(), 0, 0
        for byte in raw:
            for i in range(7, -1, -1):
                code = (code << 1) | ((byte >> i) & 1)
                bits += 1
                symbol = Hpack.HUFFMAN.get((bits, code))
                if symbol is not None:
                    out.append(symbol)
                    code, bits = 0, 0
        return out.decode(errors="replace"), pos

    def decode(self, block):
        headers, pos = {}, 0
        while pos < len(block):
            b = block[pos]
            if b & 0x80:  # indexed
                index, pos = self.integer(block, pos, 7)
                name, value = self.entry(index)
            elif b & 0xE0 == 0x20:  # dynamic table size update
                _, pos = self.integer(block, pos, 5)
                continue
            else:
                prefix = 6 if b & 0x40 else 4
                index, pos = self.integer(block, pos, prefix)
                if index:
                    name = self.entry(index)[0]
                else:
                    name, pos = self.string(block, pos)
                value, pos = self.string(block, pos)
                if b & 0x40:  # incremental indexing
                    self.dynamic.insert(0, (name, value))
            headers[name] = value
        return headers


# ---------------------------------------------------------------- quota


def probe_quota(args, table):
    share = 1 << 20
    settings = {"FUSION_API_KEYS": f"{ACME}=acme,{GLOBEX}=globex",
                "FUSION_SESSION_MEMORY_BYTES_PER_TENANT": str(share)}
    section("per-tenant bytes of the memory store", settings)
    rng = random.Random(11)
    radar = radar_2d()
    spec = {"kind": "plot_fusion", "radars": [radar], "tracker": {"default_height_m": 8_000.0}}
    # 40 aircraft: three scans make 40 tracks and a session of some 100 kB.
    targets = [(-40_000.0 + 2_000.0 * i, 40_000.0 + 1_000.0 * i, 150.0, 0.0) for i in range(40)]
    scans = [plots_2d(radar, targets, 8.0, 8_000.0, rng)[40 * k:40 * (k + 1)] for k in range(3)]

    def fill(headers):
        """Sessions of three scans each until a 429; (sessions whole, the
        refusal's status and detail, the bytes of the first session)."""
        whole, first = 0, None
        for _ in range(100):
            status, out = srv.json("POST", "/v1/sessions", spec, headers)
            if status != 201:
                return whole, status, (out or {}).get("detail", ""), first
            for i, plots in enumerate(scans):
                status, body = srv.json("POST", f"/v1/sessions/{out['id']}/batches",
                                        {"sequence": i + 1, "plots": plots}, headers)
                if status != 200:
                    return whole, status, (body or {}).get("detail", ""), first
            if first is None:
                first = srv.json("GET", f"/v1/sessions/{out['id']}", headers=headers,
                                 expect=200)[1]["encoded_bytes"]
            whole += 1
        return whole, None, "", first

    with Server(args.binary, settings) as srv:
        acme, refused, detail, size = fill({"authorization": f"Bearer {ACME}"})
        globex = {"authorization": f"Bearer {GLOBEX}"}
        other, out = srv.json("POST", "/v1/sessions", spec, globex)
        pushed = srv.json("POST", f"/v1/sessions/{out['id']}/batches",
                          {"sequence": 1, "plots": scans[0]}, globex)[0] if other == 201 else None
    table.add("one tenant fills its 1 MiB of the memory store, another goes on",
              f"acme: {acme} sessions of 3 scans × 40 plots ({size:,} bytes each) whole, then "
              f"{refused} (\"{detail[:110]}…\"); globex: create {other}, batch {pushed}",
              refused == 429 and "FUSION_SESSION_MEMORY_BYTES_PER_TENANT" in detail
              and other == 201 and pushed == 200,
              "a 429 naming the limit for the full tenant; the other tenant served")


# ---------------------------------------------------------------- budgets


def slow_jpda(scans):
    """24 scalar tracks at 0 and `scans` sensors of 24 measurements near 0:
    every scan is one cluster of 24 tracks whose exact hypothesis tree runs
    into its 2·10⁶-edge budget (tests/api/hostile.rs)."""
    tracks = [{"id": f"t{i}", "state": [0.0], "covariance": [[1.0]]} for i in range(24)]
    sensors = [{"id": f"s{s}", "kind": "linear", "h": [[1.0]], "r": [[1.0]],
                "detection_probability": 0.9, "clutter_density": 0.1,
                "measurements": [{"z": [(j - 12.0) * 0.01]} for j in range(24)]}
               for s in range(scans)]
    return {"tracks": tracks, "sensors": sensors}


SMALL = {"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}


def probe_budgets(args, table):
    section("budgets", {})
    with Server(args.binary) as srv:
        srv.request("POST", "/v1/jpda/update", slow_jpda(1) | {"tracks": slow_jpda(1)["tracks"][:2]})
        hwm0 = srv.kib("VmHWM")
        status, _, body, took = srv.request("POST", "/v1/jpda/update", slow_jpda(1))
        hwm1 = srv.kib("VmHWM")
        out = json.loads(body)
        clusters = [c for s in out.get("sensors", []) for c in s.get("clusters", [])]
        fallbacks = sorted({str(c.get("fallback")) for c in clusters})
        table.add("exact JPDA, one 24 × 24 cluster over the 2,000,000-edge budget",
                  f"{status} in {took:.2f} s, cluster fallback {fallbacks}; peak RSS "
                  f"{hwm0 / 1024:.0f} → {hwm1 / 1024:.0f} MiB",
                  status == 200 and fallbacks == ["too_many_hypotheses"]
                  and (hwm1 - hwm0) / 1024 < 256,
                  "refused inside the loop: falls back, memory bounded (before: one step "
                  "could allocate gigabytes)")

        def node(name):
            return {"id": name, "tracks": [
                {"id": f"{name}{i}", "samples": [
                    {"t": 0.0, "state": [0.0, 0.0], "covariance": [[1.0, 0.0], [0.0, 1.0]]}]}
                for i in range(1001)]}
        req = {"state_layout": ["x", "y"],
               "method": {"kind": "independent_double_threshold", "rule": {"l": 1, "r": 1}},
               "nodes": [node("a"), node("b")]}
        status, _, body, took = srv.request("POST", "/v1/correlation/tracks", req)
        problem = json.loads(body)
        fields = [e["field"] for e in problem.get("errors", [])]
        message = problem.get("errors", [{}])[0].get("message", "")
        table.add("correlation, 2 × 1,001 co-located tracks (1,002,001 candidate pairs)",
                  f"{status} in {took:.2f} s, {len(body)} bytes, fields {fields}: "
                  f"\"{message[:100]}\"",
                  status == 422 and fields == ["nodes"] and "candidate pairs" in message,
                  "a 422 naming the field, answered fast")

    settings = {"FUSION_REQUEST_TIMEOUT_S": "1", "FUSION_MAX_IN_FLIGHT": "1"}
    section("a request past its timeout", settings)
    with Server(args.binary, settings) as srv:
        # Scans enough to compute for well over the timeout in a release build.
        slow = slow_jpda(args.slow_scans)
        start = time.monotonic()
        status, _, _, took = srv.request("POST", "/v1/jpda/update", slow)
        statuses = {}
        while True:
            small, _, _, _ = srv.request("POST", "/v1/correlation/rules/evaluate", SMALL)
            statuses[small] = statuses.get(small, 0) + 1
            if small == 200 or time.monotonic() - start > 120:
                break
            time.sleep(0.01)
        served = time.monotonic() - start
        cancelled = srv.metric("compute_jobs_cancelled_total")
    # Its computation alone: the same request under a generous timeout.
    with Server(args.binary, {"FUSION_REQUEST_TIMEOUT_S": "300"}) as srv:
        _, _, _, alone = srv.request("POST", "/v1/jpda/update", slow, timeout=300)
    table.add(f"JPDA update of {args.slow_scans} scans ({alone:.1f} s of compute) under a 1 s "
              "timeout, one in-flight slot",
              f"{status} at {took:.2f} s; a small request served {served:.2f} s after the slow one "
              f"was sent ({', '.join(f'{v} × {k}' for k, v in sorted(statuses.items()))}); "
              f"{cancelled:.0f} computation stopped",
              status == 504 and served < 2.5 and cancelled >= 1 and alone > 2.5,
              "504, the computation stops and the slot is free within a scan")


# ---------------------------------------------------------------- main

PROBES = {
    "memory": lambda a, t: probe_memory(a, t, a.h2),
    "memory-h2": lambda a, t: probe_memory(a, t, True),
    "asterix": probe_asterix,
    "amplify": probe_amplify,
    "watchers": probe_watchers,
    "tracks": probe_tracks,
    "tenancy": probe_tenancy,
    "quota": probe_quota,
    "budgets": probe_budgets,
}
ALL = ["memory", "memory-h2", "asterix", "amplify", "watchers", "tracks", "tenancy", "quota",
       "budgets"]


def main():
    target = os.environ.get("CARGO_TARGET_DIR", "target")
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--binary", default=os.path.join(target, "release", "radar-fusion"))
    parser.add_argument("--probes", default=",".join(ALL),
                        help=f"comma-separated, of {', '.join(ALL)} (default: all)")
    parser.add_argument("--connections", type=int, default=120,
                        help="memory: connections (HTTP/1.1), or streams on one connection")
    parser.add_argument("--h2", action="store_true",
                        help="memory: the bombs as streams of one HTTP/2 connection")
    parser.add_argument("--hold-s", type=float, default=6.0,
                        help="memory: how long the bodies are held "
                             "(under FUSION_BODY_READ_TIMEOUT_S, 10 s by default)")
    parser.add_argument("--asterix-pace-s", type=float, default=0.1,
                        help="asterix: seconds between datagrams (their times are 1 s apart)")
    parser.add_argument("--slow-scans", type=int, default=32,
                        help="budgets: scans of the JPDA update that runs past its timeout (at most 32)")
    args = parser.parse_args()
    if not os.access(args.binary, os.X_OK):
        sys.exit(f"no binary at {args.binary}: cargo build --release --bin radar-fusion")
    table = Table()
    print(f"binary: {args.binary}")
    for name in args.probes.split(","):
        if name not in PROBES:
            sys.exit(f"unknown probe {name!r}: one of {', '.join(ALL)}")
        try:
            PROBES[name](args, table)
        except Exception as e:  # a probe that breaks is a failed row, not a stop
            table.add(name, f"the probe broke: {e.__class__.__name__}: {e}", False, "–")
    return 1 if table.print() else 0


if __name__ == "__main__":
    sys.exit(main())
