#!/usr/bin/env python3
"""Touch aluminium on one finger of a running `thermode serve`, watch the finger cool, and release it.

Standard library only: a minimal WebSocket client (RFC 6455: handshake, masked text frames, ping/pong, close)
written with `socket`, `base64`, `hashlib` and `os`. The contact API is documented in docs/api.md.

    thermode serve &                      # or: thermode demo
    python3 examples/touch_aluminium.py   # channel 1 (the index finger), 3 s of contact

Options: --url ws://HOST:PORT/api/ws, --token T (for a daemon started with --token), --channel N,
--material NAME, --hold SECONDS.
"""

import argparse
import base64
import hashlib
import json
import os
import socket
import struct
import sys
import time
from urllib.parse import quote, urlsplit

GUID = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11"


class WebSocket:
    """A blocking WebSocket client: enough for JSON text messages."""

    def __init__(self, url, token=None, timeout_s=10.0):
        parts = urlsplit(url)
        if parts.scheme != "ws":
            raise ValueError("only ws:// URLs are supported (the daemon speaks plain HTTP)")
        host, port = parts.hostname or "127.0.0.1", parts.port or 80
        path = parts.path or "/"
        if parts.query:
            path += "?" + parts.query
        self.sock = socket.create_connection((host, port), timeout=timeout_s)
        key = base64.b64encode(os.urandom(16)).decode()
        lines = [
            f"GET {path} HTTP/1.1",
            f"Host: {host}:{port}",
            "Upgrade: websocket",
            "Connection: Upgrade",
            f"Sec-WebSocket-Key: {key}",
            "Sec-WebSocket-Version: 13",
        ]
        if token:
            lines.append(f"Authorization: Bearer {token}")
        self.sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("the daemon closed the connection during the handshake")
            head += chunk
        head, self.buffer = head.split(b"\r\n\r\n", 1)
        status_line, *header_lines = head.decode("latin-1").split("\r\n")
        if " 101 " not in status_line + " ":
            raise ConnectionError(f"handshake refused: {status_line}")
        headers = {k.strip().lower(): v.strip() for k, v in (h.split(":", 1) for h in header_lines if ":" in h)}
        want = base64.b64encode(hashlib.sha1((key + GUID).encode()).digest()).decode()
        if headers.get("sec-websocket-accept") != want:
            raise ConnectionError("bad Sec-WebSocket-Accept")

    def _read(self, n):
        while len(self.buffer) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("connection closed")
            self.buffer += chunk
        data, self.buffer = self.buffer[:n], self.buffer[n:]
        return data

    def _send_frame(self, opcode, payload):
        mask = os.urandom(4)
        header = bytes([0x80 | opcode])
        n = len(payload)
        if n < 126:
            header += bytes([0x80 | n])
        elif n < 65536:
            header += bytes([0x80 | 126]) + struct.pack("!H", n)
        else:
            header += bytes([0x80 | 127]) + struct.pack("!Q", n)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(header + mask + masked)

    def send_json(self, message):
        self._send_frame(0x1, json.dumps(message).encode())

    def recv_json(self):
        """The next text message as JSON (answers pings; raises on close)."""
        message = b""
        while True:
            b0, b1 = self._read(2)
            opcode, n = b0 & 0x0F, b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack("!H", self._read(2))
            elif n == 127:
                (n,) = struct.unpack("!Q", self._read(8))
            payload = self._read(n)  # the server does not mask its frames
            if opcode == 0x9:
                self._send_frame(0xA, payload)
            elif opcode == 0x8:
                raise ConnectionError("the daemon closed the connection")
            elif opcode in (0x1, 0x0):
                message += payload
                if b0 & 0x80:
                    return json.loads(message)

    def close(self):
        try:
            self._send_frame(0x8, struct.pack("!H", 1000))
        finally:
            self.sock.close()


def request(ws, message):
    """Sends a request and returns the reply with the same id (telemetry in between is skipped)."""
    ws.send_json(message)
    while True:
        reply = ws.recv_json()
        if reply.get("type") != "telemetry" and reply.get("id") == message["id"]:
            if reply.get("type") == "error":
                raise RuntimeError(f"{message['type']} refused: {reply['code']}: {reply['message']}")
            return reply


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="ws://127.0.0.1:8765/api/ws")
    parser.add_argument("--token", default=None)
    parser.add_argument("--channel", type=int, default=1)
    parser.add_argument("--material", default="aluminium")
    parser.add_argument("--hold", type=float, default=3.0, help="seconds of contact")
    args = parser.parse_args()
    url = args.url
    if args.token:
        url += ("&" if "?" in url else "?") + "token=" + quote(args.token, safe="")
    ws = WebSocket(url, token=args.token)
    reply = request(ws, {"type": "touch", "id": 1, "channel": args.channel, "material": args.material})
    print(f"ok touch: channel {reply['channel']} touches {reply['material']} (loop time {reply['time_s']:.2f} s)")
    request(ws, {"type": "subscribe", "id": 2, "rate_hz": 4})
    start = time.monotonic()
    while time.monotonic() - start < args.hold:
        message = ws.recv_json()
        if message.get("type") == "telemetry":
            c = message["channels"][args.channel]
            shows = c["material"] if c["contact"] else c["mode"]
            print(f"  t={message['time_s']:7.2f} s  {shows:>10}  target {c['target_skin_c']:.2f} °C  "
                  f"skin {c['skin_c']:.2f} °C  sensor {c['sensor_c']:.2f} °C  drive {c['current_a']:+.2f} A")
    request(ws, {"type": "unsubscribe", "id": 3})
    reply = request(ws, {"type": "release", "id": 4, "channel": args.channel})
    print(f"ok release: channel {reply['channel']} renders air again")
    ws.close()
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except (OSError, RuntimeError, ValueError) as e:
        print(f"touch_aluminium: {e}", file=sys.stderr)
        sys.exit(1)
