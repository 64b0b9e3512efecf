#!/usr/bin/env python3
"""A static file server on 127.0.0.1 that adds latency to every request (one thread per
connection, so concurrent requests overlap) and, optionally, injects faults at random, for the
streaming figures and the soak test.

    python3 tools/slow_http.py DIR PORT [LATENCY_MS] [FAULT_RATE]

With FAULT_RATE (0..1), that share of tile requests (not metadata.json) meets one of: 500,
429 with Retry-After: 1, 404, a truncated body, an HTML body, a PNG declaring 60000 x 60000
pixels, a stall of 3 s mid-body, or a connection closed without an answer. Faults are drawn
from a seeded generator, so runs repeat.
"""
import functools
import random
import struct
import sys
import time
import zlib
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

FAULTS = ["500", "429", "404", "truncate", "html", "absurd", "stall", "reset"]


def absurd_png():
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", 60000, 60000, 8, 6, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b"")


class Slow(SimpleHTTPRequestHandler):
    latency_s = 0.05
    fault_rate = 0.0
    rng = random.Random(5)
    protocol_version = "HTTP/1.1"

    def send_plain(self, status, body=b"", headers=()):
        self.send_response(status)
        for k, v in headers:
            self.send_header(k, v)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def do_GET(self):
        time.sleep(self.latency_s)
        fault = None
        if self.fault_rate > 0 and not self.path.endswith("metadata.json"):
            if self.rng.random() < self.fault_rate:
                fault = self.rng.choice(FAULTS)
        if fault is None:
            return super().do_GET()
        if fault == "500":
            return self.send_plain(500)
        if fault == "429":
            return self.send_plain(429, headers=[("Retry-After", "1")])
        if fault == "404":
            return self.send_plain(404)
        if fault == "html":
            return self.send_plain(200, b"<html><body>overloaded</body></html>", [("Content-Type", "text/html")])
        if fault == "absurd":
            return self.send_plain(200, absurd_png(), [("Content-Type", "image/png")])
        if fault == "reset":
            self.close_connection = True
            return
        path = self.translate_path(self.path)
        try:
            with open(path, "rb") as f:
                body = f.read()
        except OSError:
            return self.send_plain(404)
        self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body[: len(body) // 2])
        self.wfile.flush()
        if fault == "stall":
            time.sleep(3)
        self.close_connection = True

    def log_message(self, *args):
        pass

    def handle(self):
        try:
            super().handle()
        except (ConnectionError, BrokenPipeError):
            pass


def main():
    root, port = sys.argv[1], int(sys.argv[2])
    Slow.latency_s = (float(sys.argv[3]) if len(sys.argv) > 3 else 50.0) / 1000.0
    Slow.fault_rate = float(sys.argv[4]) if len(sys.argv) > 4 else 0.0
    handler = functools.partial(Slow, directory=root)
    ThreadingHTTPServer.daemon_threads = True
    with ThreadingHTTPServer(("127.0.0.1", port), handler) as server:
        server.serve_forever()


if __name__ == "__main__":
    main()
