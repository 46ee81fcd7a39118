#!/usr/bin/env python3
"""Hostile-client probes of issue 53 against a release binary (stdlib only).

Memory before admission: N connections (default 120) each POST a gzip body
of about 16 kB that inflates to 15.9 MiB (a JSON request padded with
spaces, under the default 16 MiB body limit once decompressed), send all
of it but its last 8 bytes (the gzip trailer) and hold it open. The
server's peak resident memory (VmHWM of /proc/<pid>/status) is printed,
with how each connection was answered while held.

The same bombs over HTTP/2 (`--h2`): one connection opens N streams (the
issue's "the same amplification reaches HTTP/2 streams"), each a bomb held
without its last 8 bytes; the server's announced stream cap
(SETTINGS_MAX_CONCURRENT_STREAMS) and the streams it refused are printed.

Usage: checks/hostile_probes.py [--binary PATH] [--connections N] [--h2]
The binary defaults to $CARGO_TARGET_DIR/release/radar-fusion (target/ when
unset); build it first with `cargo build --release --bin radar-fusion`.
Extra server settings go in the environment (FUSION_*), as for the server.
"""

import argparse
import gzip
import os
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


def main():
    target = os.environ.get("CARGO_TARGET_DIR", "target")
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--binary", default=os.path.join(target, "release", "radar-fusion"))
    parser.add_argument("--connections", type=int, default=120,
                        help="connections (HTTP/1.1), or streams on one connection (--h2)")
    parser.add_argument("--h2", action="store_true",
                        help="the bombs as streams of one HTTP/2 connection")
    parser.add_argument("--hold-s", type=float, default=6.0,
                        help="how long the bodies are held while RSS is sampled "
                             "(under FUSION_BODY_READ_TIMEOUT_S, 10 s by default)")
    args = parser.parse_args()

    http_port, grpc_port = free_port(), free_port()
    env = dict(os.environ)
    env.update({
        "FUSION_HTTP_ADDR": f"127.0.0.1:{http_port}",
        "FUSION_GRPC_ADDR": f"127.0.0.1:{grpc_port}",
        "FUSION_LOG": env.get("FUSION_LOG", "warn"),
    })
    proc = subprocess.Popen([args.binary], env=env, stdout=subprocess.DEVNULL)
    try:
        wait_until_serving(http_port, proc)
        rss_idle = status_kib(proc.pid, "VmRSS")
        body = bomb()
        head = (
            f"POST {PATH} HTTP/1.1\r\nHost: probe\r\nContent-Type: application/json\r\n"
            f"Content-Encoding: gzip\r\nContent-Length: {len(body)}\r\n\r\n"
        ).encode()
        socks, h2 = [], None
        if args.h2:
            h2 = threading.Thread(target=lambda: holder.append(
                H2Bombs(http_port, args.connections, body)), daemon=True)
            holder = []
            h2.start()
        else:
            for _ in range(args.connections):
                s = socket.create_connection(("127.0.0.1", http_port))
                s.sendall(head + body[:-8])
                socks.append(s)
        rss_peak_sampled = 0
        deadline = time.monotonic() + args.hold_s
        while time.monotonic() < deadline:
            rss_peak_sampled = max(rss_peak_sampled, status_kib(proc.pid, "VmRSS"))
            time.sleep(0.1)
        hwm = status_kib(proc.pid, "VmHWM")
        outcomes = {}
        for s in socks:
            line = answered(s) or "held (no answer yet)"
            outcomes[line] = outcomes.get(line, 0) + 1
        for s in socks:
            s.close()
        if h2 is not None:
            h2.join(timeout=1)
            bombs = holder[0] if holder else None
            if bombs is not None:
                with bombs.lock:
                    outcomes["HTTP/2 streams answered (503 or other)"] = bombs.answered
                    outcomes["HTTP/2 streams reset by the server"] = bombs.refused
                    outcomes[f"HTTP/2 SETTINGS_MAX_CONCURRENT_STREAMS announced: {bombs.max_streams}"] = 1
                bombs.sock.close()
        print(f"binary: {args.binary}")
        what = "streams on one HTTP/2 connection" if args.h2 else "HTTP/1.1 connections"
        print(f"probe: {args.connections} {what}, each a {len(body)}-byte gzip body "
              f"inflating to {INFLATED / 2**20:.2f} MiB, held without its last 8 bytes "
              f"for {args.hold_s:.0f} s")
        print(f"RSS idle: {rss_idle / 1024:.0f} MiB")
        print(f"RSS peak while held (VmRSS sampled every 0.1 s): {rss_peak_sampled / 1024:.0f} MiB")
        print(f"peak RSS (VmHWM): {hwm / 1024:.0f} MiB")
        for line, n in sorted(outcomes.items()):
            print(f"  {n:4d} × {line}")
        limit_mib = 600
        verdict = "holds" if hwm / 1024 < limit_mib else "FAILS"
        print(f"under {limit_mib} MiB: {verdict}")
        return 0 if verdict == "holds" else 1
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()


if __name__ == "__main__":
    sys.exit(main())
