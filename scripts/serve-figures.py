#!/usr/bin/env python3
"""The figures docs/serve.md gives for `ferret serve` under abuse, measured on a real server on
127.0.0.1: resident memory after many large scene uploads, start-up time with them stored, and a
normal client's latency while many idle connections are held open.

    scripts/serve-figures.py --bin target/release/ferret [--uploads 600] [--side 95] \
        [--idle 1000] [--requests 300] [--server-nofile 1024] [--json] [-- SERVE_ARGS...]

Each upload is one square room `--side` metres wide (at the default 0.05 m resolution a 95 m
room is 3.6 M cells, under the default limit of 4 M) with two containers. Standard library only.
"""

import argparse
import json
import os
import re
import resource
import socket
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENE = os.path.join(ROOT, "examples", "apartment", "scene.yaml")


def square(name, side):
    return {
        "ferret_scene": 1,
        "name": name,
        "rooms": [
            {
                "name": "hall",
                "type": "LivingRoom",
                "polygon": [[0, 0], [side, 0], [side, side], [0, side]],
            }
        ],
        "containers": [
            {"id": "a", "type": "Dresser", "pose": [side / 2, side / 2, 0]},
            {"id": "b", "type": "Bed", "pose": [1.0, 1.0, 0]},
        ],
        "start": [side / 3, side / 3, 0],
    }


class Server:
    """`ferret serve` on the apartment; `stop()` ends it."""

    def __init__(self, binary, db, extra, nofile):
        started = time.monotonic()
        self.proc = subprocess.Popen(
            [
                binary,
                "serve",
                "--scene",
                SCENE,
                "--strategies",
                "optimistic+greedy,model/uniform",
                "--listen",
                "127.0.0.1:0",
                "--db",
                db,
            ]
            + extra,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (nofile, nofile)),
            env={k: v for k, v in os.environ.items() if k != "FERRET_SERVE_TOKEN"},
        )
        line = self.proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:(\d+)", line)
        if not m:
            self.stop()
            sys.exit(f"ferret serve printed no address: {line!r}")
        self.port = int(m.group(1))
        self.listening_s = time.monotonic() - started
        status, _ = self.request("GET", "/scenes")
        if status != 200:
            self.stop()
            sys.exit(f"GET /scenes: {status}")
        self.ready_s = time.monotonic() - started

    def request(self, method, path, body=None, timeout=120):
        data = b"" if body is None else json.dumps(body).encode()
        with socket.create_connection(("127.0.0.1", self.port), timeout=timeout) as s:
            s.sendall(
                f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{self.port}\r\nConnection: close\r\n"
                f"Content-Type: application/json\r\nContent-Length: {len(data)}\r\n\r\n".encode()
                + data
            )
            out = b""
            while True:
                chunk = s.recv(65536)
                if not chunk:
                    break
                out += chunk
        head = out.split(b" ", 2)
        return (int(head[1]) if len(head) > 1 and head[1].isdigit() else 0), out

    def rss_mib(self, field="VmRSS"):
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) / 1024
        return float("nan")

    def stop(self):
        self.proc.kill()
        self.proc.wait()


def percentile(sorted_values, p):
    return sorted_values[
        min(len(sorted_values) - 1, int(round(p / 100 * (len(sorted_values) - 1))))
    ]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", required=True, help="the ferret binary")
    ap.add_argument("--uploads", type=int, default=600)
    ap.add_argument("--side", type=float, default=95.0)
    ap.add_argument("--idle", type=int, default=1000)
    ap.add_argument("--requests", type=int, default=300)
    ap.add_argument(
        "--server-nofile",
        type=int,
        default=1024,
        help="the server's open-file limit (a common default)",
    )
    ap.add_argument("--json", action="store_true")
    ap.add_argument("serve_args", nargs="*", help="more `ferret serve` arguments (after --)")
    args = ap.parse_args()
    # The idle connections need descriptors of their own.
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (hard, hard))
    figures = {
        "uploads": args.uploads,
        "side_m": args.side,
        "idle": args.idle,
        "server_nofile": args.server_nofile,
    }
    with tempfile.TemporaryDirectory() as tmp:
        db = os.path.join(tmp, "serve.sqlite")
        server = Server(args.bin, db, args.serve_args, args.server_nofile)
        figures["rss_start_mib"] = round(server.rss_mib(), 1)
        refused = {}
        started = time.monotonic()
        for i in range(args.uploads):
            status, _ = server.request("POST", "/scenes", {"scene": square(f"sq{i}", args.side)})
            if status not in (200, 201):
                refused[status] = refused.get(status, 0) + 1
        figures["upload_s"] = round(time.monotonic() - started, 1)
        figures["uploads_refused"] = refused
        figures["rss_after_uploads_mib"] = round(server.rss_mib(), 1)
        figures["rss_peak_mib"] = round(server.rss_mib("VmHWM"), 1)
        server.stop()

        server = Server(args.bin, db, args.serve_args, args.server_nofile)
        figures["restart_listening_s"] = round(server.listening_s, 2)
        figures["restart_ready_s"] = round(server.ready_s, 2)
        figures["rss_after_restart_mib"] = round(server.rss_mib(), 1)

        idle = []
        for _ in range(args.idle):
            try:
                idle.append(socket.create_connection(("127.0.0.1", server.port), timeout=5))
            except OSError:
                break
        figures["idle_opened"] = len(idle)
        time.sleep(0.5)
        times, failures = [], 0
        for _ in range(args.requests):
            t = time.monotonic()
            try:
                status, _ = server.request("GET", "/scenes", timeout=30)
            except OSError:
                status = 0
            times.append(time.monotonic() - t)
            failures += status != 200
        times.sort()
        figures["requests"] = args.requests
        figures["request_failures"] = failures
        figures["p50_ms"] = round(percentile(times, 50) * 1000, 1)
        figures["p99_ms"] = round(percentile(times, 99) * 1000, 1)
        for s in idle:
            s.close()
        server.stop()
    if args.json:
        print(json.dumps(figures, indent=2))
    else:
        for k, v in figures.items():
            print(f"{k:24} {v}")


if __name__ == "__main__":
    main()
