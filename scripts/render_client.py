#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Asks `webfusion serve --map MAP.wfm` what a virtual Kinect sees at given poses.

Standard library only, so a planner in Python can copy the `Client` class as it is:

    from render_client import Client
    with Client("ws://127.0.0.1:8080/ws") as client:
        view = client.render(pose=(0, 0, 0, 0, 0, 0, 1), intrinsics=(525, 525, 319.5, 239.5),
                             size=(640, 480))
        print(view.valid_pixels, view.depth_m(320, 240))

From the command line it renders one view per `--pose` (or per line of a TUM trajectory
given with `--poses`), writes each as a 16-bit PNG at the requested depth scale (and the
map's colour as an 8-bit PNG with `--color`) and prints one JSON line per view:

    scripts/render_client.py ws://127.0.0.1:8080/ws --pose 0,0,0,0,0,0,1 --out views/

A pose is `tx,ty,tz,qx,qy,qz,qw`: the camera's pose in the map's frame (world_from_camera;
camera x right, y down, z forward), metres, the TUM convention. The wire format is the
`RenderRequest` / `RenderReply` messages of `core/src/protocol.rs` (protocol version 3).
With `--unknown` (a server started with `--occupancy G.json`) each view also says which
pixels looked through never-observed space (unknown_NNNNNN.png: 255 marked, 0 not).
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
import zlib
from array import array
from urllib.parse import urlsplit

PROTOCOL_VERSION = 3
KIND_HELLO, KIND_FRAME, KIND_STATUS, KIND_ERROR, KIND_RENDER_REPLY = 1, 2, 3, 4, 5
KIND_RENDER_REQUEST = 17
FAILURES = {1: "no map", 2: "invalid request", 3: "render failed"}
# Largest message a server sends (protocol MAX_SERVER_MESSAGE_BYTES) plus frame headers.
MAX_MESSAGE_BYTES = (16 << 20) + 1024


class RenderError(Exception):
    """The server answered a render request without a view."""

    def __init__(self, request_id, code, message):
        super().__init__(f"request {request_id}: {FAILURES.get(code, code)}: {message}")
        self.request_id, self.code, self.message = request_id, code, message


class ServerClosed(Exception):
    """The server closed the connection (with its error message when it sent one)."""


class View:
    """A rendered view: depth in raw units (0: no return), optionally the map's colour and
    the unknown mask."""

    def __init__(self, request_id, width, height, units_per_metre, radial, depth_le, rgb, unknown=None):
        self.request_id, self.width, self.height = request_id, width, height
        self.units_per_metre, self.radial = units_per_metre, radial
        self.depth_le = depth_le  # row-major u16 little-endian, as on the wire
        self.rgb = rgb  # packed RGB8 or None
        self.unknown = unknown  # a byte per pixel, 255: the ray crossed never-observed space; or None
        self.depth = array("H")
        self.depth.frombytes(depth_le)
        if sys.byteorder == "big":
            self.depth.byteswap()

    @property
    def valid_pixels(self):
        return sum(1 for u in self.depth if u)

    def depth_m(self, x, y):
        """Depth (or distance, when radial) at pixel (x, y) in metres; None without a return."""
        u = self.depth[y * self.width + x]
        return u / self.units_per_metre if u else None

    def summary(self):
        valid = [u for u in self.depth if u]
        scale = 1.0 / self.units_per_metre
        return {
            "request_id": self.request_id,
            "width": self.width,
            "height": self.height,
            "radial": self.radial,
            "valid_pixels": len(valid),
            "valid_percent": round(100.0 * len(valid) / len(self.depth), 3),
            "min_m": min(valid) * scale if valid else None,
            "max_m": max(valid) * scale if valid else None,
            "mean_m": sum(valid) * scale / len(valid) if valid else None,
            "depth_sha256": hashlib.sha256(self.depth_le).hexdigest(),
            "unknown_pixels": None if self.unknown is None else sum(1 for m in self.unknown if m),
        }


class WebSocket:
    """A minimal RFC 6455 client: binary messages, fragmentation, ping/pong, close."""

    def __init__(self, url, timeout_s=60.0):
        parts = urlsplit(url)
        if parts.scheme != "ws":
            raise ValueError(f"{url}: only ws:// URLs (put a TLS proxy in front for wss://)")
        host, port = parts.hostname, parts.port or 80
        path = (parts.path or "/") + (f"?{parts.query}" if parts.query else "")
        self.sock = socket.create_connection((host, port), timeout=timeout_s)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
             f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode()
        )
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ServerClosed("the server closed the connection during the handshake")
            head += chunk
            if len(head) > 65536:
                raise ServerClosed("the handshake reply is too long")
        head, rest = head.split(b"\r\n\r\n", 1)
        self.buffer = bytearray(rest)
        lines = head.decode("latin-1").split("\r\n")
        if not lines[0].startswith("HTTP/1.1 101"):
            raise ServerClosed(f"the server refused the WebSocket: {lines[0]} (wrong ?token= or path?)")
        headers = {k.strip().lower(): v.strip() for k, v in (line.split(":", 1) for line in lines[1:] if ":" in line)}
        expected = base64.b64encode(hashlib.sha1((key + "258EAFA5-E914-47DA-95CA-C5AB0DC85B11").encode()).digest()).decode()
        if headers.get("sec-websocket-accept") != expected:
            raise ServerClosed("the server's handshake does not answer our key")

    def _exact(self, n):
        while len(self.buffer) < n:
            chunk = self.sock.recv(max(65536, n - len(self.buffer)))
            if not chunk:
                raise ServerClosed("the server closed the connection")
            self.buffer += chunk
        out = bytes(self.buffer[:n])
        del self.buffer[:n]
        return out

    def _send_frame(self, opcode, payload):
        n = len(payload)
        head = bytes([0x80 | opcode])
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 65536:
            head += bytes([0x80 | 126]) + struct.pack(">H", n)
        else:
            head += bytes([0x80 | 127]) + struct.pack(">Q", n)
        mask = os.urandom(4)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(head + mask + masked)

    def send_binary(self, payload):
        self._send_frame(0x2, payload)

    def recv_binary(self):
        """The next binary message (control frames are handled on the way)."""
        message, opcode = b"", None
        while True:
            b0, b1 = self._exact(2)
            fin, op, masked, n = b0 & 0x80, b0 & 0x0F, b1 & 0x80, b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack(">H", self._exact(2))
            elif n == 127:
                (n,) = struct.unpack(">Q", self._exact(8))
            if n > MAX_MESSAGE_BYTES or len(message) + n > MAX_MESSAGE_BYTES:
                raise ServerClosed(f"a {n}-byte frame is larger than any webfusion message")
            mask = self._exact(4) if masked else None
            payload = self._exact(n)
            if mask:
                payload = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
            if op == 0x8:
                code = struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else None
                raise ServerClosed(f"the server closed the connection ({code}): {payload[2:].decode('utf-8', 'replace')}")
            if op == 0x9:
                self._send_frame(0xA, payload)
                continue
            if op == 0xA:
                continue
            if op in (0x1, 0x2):
                opcode, message = op, payload
            elif op == 0x0 and opcode is not None:
                message += payload
            else:
                raise ServerClosed(f"unexpected WebSocket opcode {op}")
            if fin:
                if opcode != 0x2:
                    raise ServerClosed("the server sent a text message; the protocol is binary")
                return message

    def close(self):
        try:
            self._send_frame(0x8, struct.pack(">H", 1000))
        except OSError:
            pass
        self.sock.close()


def encode_request(request_id, pose, intrinsics, size, units_per_metre=5000.0, radial=False, color=False, depth_range_m=None, noise=None, unknown=False):
    """A RenderRequest message. `noise`: None or (seed, frame_index) for the Kinect model;
    `unknown`: also ask for the unknown mask."""
    tx, ty, tz, qx, qy, qz, qw = (float(v) for v in pose)
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    width, height = size
    out = b"WF" + bytes([PROTOCOL_VERSION, KIND_RENDER_REQUEST])
    out += struct.pack("<I7dII5f", request_id, tx, ty, tz, qx, qy, qz, qw, width, height, fx, fy, cx, cy, units_per_metre)
    out += bytes([int(radial), int(color), 0])  # depth encoding 0: raw u16 little-endian
    out += b"\x00" if depth_range_m is None else b"\x01" + struct.pack("<2f", *depth_range_m)
    out += b"\x00" if noise is None else b"\x01" + struct.pack("<2I", *noise)
    out += bytes([int(unknown)])
    return out


def decode_reply(message):
    """(request_id, View) for a render reply; None for the session's other messages (hello,
    status, frames); raises RenderError or ServerClosed for a failure or an error."""
    if message[:2] != b"WF" or len(message) < 4:
        raise ServerClosed("the server sent something that is not a webfusion message")
    if message[2] != PROTOCOL_VERSION:
        raise ServerClosed(f"the server speaks protocol version {message[2]}, this client {PROTOCOL_VERSION}")
    kind, body = message[3], message[4:]
    if kind == KIND_ERROR:
        (code, n) = struct.unpack_from("<HH", body)
        raise ServerClosed(f"server error {code}: {body[4:4 + n].decode('utf-8', 'replace')}")
    if kind != KIND_RENDER_REPLY:
        return None
    request_id, status = struct.unpack_from("<IB", body)
    at = 5
    if status != 0:
        (n,) = struct.unpack_from("<H", body, at)
        raise RenderError(request_id, status, body[at + 2:at + 2 + n].decode("utf-8", "replace"))
    width, height, units, radial, encoding, depth_len = struct.unpack_from("<IIfBBI", body, at)
    at += 18
    if encoding != 0:
        raise ServerClosed(f"depth encoding {encoding}: this client asks for raw depth only")
    depth = body[at:at + depth_len]
    at += depth_len
    if len(depth) != 2 * width * height:
        raise ServerClosed(f"a {width}x{height} view with {len(depth)} bytes of depth")
    optional = []
    for what, size in (("colour", 3 * width * height), ("unknown mask", width * height)):
        if body[at] == 1:
            (n,) = struct.unpack_from("<I", body, at + 1)
            if n != size:
                raise ServerClosed(f"a {width}x{height} view with {n} bytes of {what}")
            optional.append(body[at + 5:at + 5 + n])
            at += 5 + n
        else:
            optional.append(None)
            at += 1
    return request_id, View(request_id, width, height, units, bool(radial), depth, *optional)


class Client:
    """One WebSocket session with `webfusion serve --map`; renders are answered in order."""

    def __init__(self, url, timeout_s=60.0):
        self.ws = WebSocket(url, timeout_s)
        self.next_id = 1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.ws.close()

    def render(self, pose, intrinsics, size, **options):
        """The view at `pose` (tx, ty, tz, qx, qy, qz, qw); options as `encode_request`."""
        request_id, self.next_id = self.next_id, self.next_id + 1
        self.ws.send_binary(encode_request(request_id, pose, intrinsics, size, **options))
        while True:
            reply = decode_reply(self.ws.recv_binary())
            if reply is not None and reply[0] == request_id:
                return reply[1]


def png(width, height, color_type, rows, bit_depth=None):
    """A PNG of `rows` (bytes per row, already in PNG sample order), no filtering; grey
    (colour type 0) is 16-bit unless `bit_depth` says otherwise."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    if bit_depth is None:
        bit_depth = 16 if color_type == 0 else 8
    raw = b"".join(b"\x00" + row for row in rows)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, bit_depth, color_type, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def depth_png(view):
    big_endian = array("H", view.depth)
    if sys.byteorder == "little":
        big_endian.byteswap()
    data = big_endian.tobytes()
    stride = 2 * view.width
    return png(view.width, view.height, 0, [data[y * stride:(y + 1) * stride] for y in range(view.height)])


def rgb_png(view):
    stride = 3 * view.width
    return png(view.width, view.height, 2, [view.rgb[y * stride:(y + 1) * stride] for y in range(view.height)])


def gray_png(width, height, mask):
    return png(width, height, 0, [mask[y * width:(y + 1) * width] for y in range(height)], bit_depth=8)


def numbers(text, count, what):
    values = [float(v) for v in text.split(",")]
    if len(values) != count:
        raise argparse.ArgumentTypeError(f"{what} takes {count} comma-separated numbers, not {text!r}")
    return values


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("url", help="the server's WebSocket, e.g. ws://127.0.0.1:8080/ws (add ?token=... when it has one)")
    parser.add_argument("--pose", action="append", default=[], help="tx,ty,tz,qx,qy,qz,qw (repeatable; write --pose=-1,... when it starts with a minus)")
    parser.add_argument("--poses", help="a TUM trajectory file: one view per line 'timestamp tx ty tz qx qy qz qw'")
    parser.add_argument("--size", default="640x480", help="WxH (default 640x480)")
    parser.add_argument("--intrinsics", help="fx,fy,cx,cy in pixels (default the Kinect's 525 px at 640x480, scaled to --size)")
    parser.add_argument("--depth-scale", type=float, default=5000.0, help="raw depth units per metre (TUM: 5000)")
    parser.add_argument("--radial", action="store_true", help="distance along each ray instead of depth along z")
    parser.add_argument("--range", help="near,far in metres (default the Kinect model's)")
    parser.add_argument("--noise", choices=["none", "kinect"], default="none")
    parser.add_argument("--seed", type=int, default=0, help="the noise's seed")
    parser.add_argument("--frame-index", type=int, default=0, help="the first view's noise frame index (the next views count up)")
    parser.add_argument("--color", action="store_true", help="also fetch the map's colour")
    parser.add_argument("--unknown", action="store_true", help="also fetch the unknown mask (the server needs --occupancy)")
    parser.add_argument("--out", help="directory for depth_NNNNNN.png (and rgb_NNNNNN.png, unknown_NNNNNN.png)")
    args = parser.parse_args()

    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        parser.error(f"--size {args.size!r}: expected WxH")
    if args.intrinsics:
        intrinsics = numbers(args.intrinsics, 4, "--intrinsics")
    else:
        f = 525.0 * width / 640.0
        intrinsics = [f, f, 0.5 * width - 0.5, 0.5 * height - 0.5]
    poses = [numbers(p, 7, "--pose") for p in args.pose]
    if args.poses:
        with open(args.poses, encoding="utf-8") as lines:
            poses += [[float(v) for v in line.split()[1:8]] for line in lines if line.strip() and not line.startswith("#")]
    if not poses:
        parser.error("give at least one --pose or a --poses file")
    depth_range = numbers(args.range, 2, "--range") if args.range else None
    if args.out:
        os.makedirs(args.out, exist_ok=True)

    try:
        with Client(args.url) as client:
            for i, pose in enumerate(poses):
                noise = (args.seed, args.frame_index + i) if args.noise == "kinect" else None
                started = time.perf_counter()
                view = client.render(pose, intrinsics, (width, height), units_per_metre=args.depth_scale, radial=args.radial, color=args.color, depth_range_m=depth_range, noise=noise, unknown=args.unknown)
                summary = view.summary()
                summary["round_trip_ms"] = round(1e3 * (time.perf_counter() - started), 2)
                if args.out:
                    summary["depth_png"] = os.path.join(args.out, f"depth_{i:06d}.png")
                    with open(summary["depth_png"], "wb") as f:
                        f.write(depth_png(view))
                    if view.rgb is not None:
                        summary["rgb_png"] = os.path.join(args.out, f"rgb_{i:06d}.png")
                        with open(summary["rgb_png"], "wb") as f:
                            f.write(rgb_png(view))
                    if view.unknown is not None:
                        summary["unknown_png"] = os.path.join(args.out, f"unknown_{i:06d}.png")
                        with open(summary["unknown_png"], "wb") as f:
                            f.write(gray_png(view.width, view.height, view.unknown))
                print(json.dumps(summary), flush=True)
    except (RenderError, ServerClosed, OSError) as e:
        print(f"render_client: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
