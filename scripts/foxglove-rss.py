#!/usr/bin/env python3
"""The station's memory while live-view clients misbehave.

Starts `mech-gcs serve --demo ROBOTS --foxglove 127.0.0.1:0` (a build with
the `foxglove` feature), lets it settle, then connects VIEWERS viewers that
subscribe to every channel, read a moment and never read again, and one
client that sends PINGS WebSocket pings as fast as the station takes them
and never reads. For SECONDS it prints the station's resident memory
(VmRSS from /proc/PID/status) every 5 s; at the end, the baseline, the
peak, the last figure, how many pings the station took, and the lines
the station logged about cutting clients, each with the seconds from the
moment that client stopped reading (the pinger: from its first ping) to
its cut. Python's standard library only; asserts nothing.

    python3 scripts/foxglove-rss.py [--gcs target/debug/mech-gcs]
        [--robots 4] [--viewers 4] [--pings 1000000] [--seconds 60]
"""

import argparse
import base64
import datetime
import glob
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time


def rss_kib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def frame(opcode, payload):
    """A client's frame: final, masked."""
    mask = os.urandom(4)
    n = len(payload)
    if n < 126:
        head = struct.pack("!BB", 0x80 | opcode, 0x80 | n)
    elif n < 1 << 16:
        head = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, n)
    else:
        head = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, n)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    return head + mask + masked


def read_exact(sock, n):
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("closed")
        buf += chunk
    return buf


def read_frame(sock):
    """A server's frame (unmasked): opcode and payload."""
    b0, b1 = read_exact(sock, 2)
    n = b1 & 0x7F
    if n == 126:
        (n,) = struct.unpack("!H", read_exact(sock, 2))
    elif n == 127:
        (n,) = struct.unpack("!Q", read_exact(sock, 8))
    return b0 & 0x0F, read_exact(sock, n)


def connect(addr):
    host, port = addr.rsplit(":", 1)
    sock = socket.create_connection((host, int(port)))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        (
            f"GET / HTTP/1.1\r\nHost: {addr}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            "Sec-WebSocket-Version: 13\r\n"
            "Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n"
        ).encode()
    )
    reply = b""
    while b"\r\n\r\n" not in reply:
        chunk = sock.recv(1)
        if not chunk:
            raise ConnectionError("handshake refused")
        reply += chunk
    if b" 101 " not in reply.split(b"\r\n", 1)[0]:
        raise ConnectionError(reply.decode(errors="replace"))
    return sock


def read_answering(sock):
    """A server's frame, a ping answered as a browser answers it."""
    op, payload = read_frame(sock)
    if op == 9:
        sock.sendall(frame(10, payload))
    return op, payload


def stalled_viewer(addr, robots):
    """Subscribes to every channel, reads (answering pings) for a few
    seconds, then never again."""
    sock = connect(addr)
    channels = {}
    sock.settimeout(5)
    deadline = time.time() + 20
    # Every robot's pose and telemetry, and the station's own four.
    while len(channels) < 2 * robots + 4 and time.time() < deadline:
        try:
            op, payload = read_answering(sock)
        except socket.timeout:
            continue
        if op == 1:
            msg = json.loads(payload)
            if msg.get("op") == "advertise":
                for ch in msg["channels"]:
                    channels[ch["topic"]] = ch["id"]
    subs = [{"id": i, "channelId": c} for i, c in enumerate(channels.values())]
    sub = json.dumps({"op": "subscribe", "subscriptions": subs}).encode()
    sock.sendall(frame(1, sub))
    end = time.time() + 5
    while time.time() < end:
        try:
            read_answering(sock)
        except socket.timeout:
            pass
    return sock, len(channels), time.time()


class Pinger(threading.Thread):
    """Sends pings as fast as the station takes them; never reads."""

    def __init__(self, addr, pings):
        super().__init__(daemon=True)
        self.sock = connect(addr)
        self.pings = pings
        self.sent = 0
        self.stop = False

    def run(self):
        burst_len = 1000
        burst = b"".join(frame(9, b"p" * 120) for _ in range(burst_len))
        self.sock.settimeout(0.5)
        while self.sent < self.pings and not self.stop:
            view = memoryview(burst)
            try:
                while view and not self.stop:
                    try:
                        n = self.sock.send(view)
                    except socket.timeout:
                        continue
                    view = view[n:]
            except OSError:
                return
            self.sent += burst_len


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--gcs", default="target/debug/mech-gcs")
    p.add_argument("--robots", type=int, default=4)
    p.add_argument("--viewers", type=int, default=4)
    p.add_argument("--pings", type=int, default=1_000_000)
    p.add_argument("--seconds", type=int, default=60)
    a = p.parse_args()

    state = tempfile.mkdtemp(prefix="mech-rss-")
    station = subprocess.Popen(
        [a.gcs, "serve", "--demo", str(a.robots), "--udp", "127.0.0.1:0",
         "--tcp", "127.0.0.1:0", "--foxglove", "127.0.0.1:0",
         "--socket", os.path.join(state, "gcs.sock")],
        env={**os.environ, "XDG_STATE_HOME": state},
        stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
        stderr=open(os.path.join(state, "stderr.log"), "w"),
    )
    try:
        line = station.stdout.readline().decode()
        if "ws://" not in line:
            sys.exit(f"no live view in the ready line: {line!r}")
        addr = line.split("ws://", 1)[1].split()[0]
        time.sleep(5)
        base = rss_kib(station.pid)
        print(f"station pid {station.pid}, live view {addr}, "
              f"{a.robots} robots: baseline {base / 1024:.1f} MiB")
        viewers = [stalled_viewer(addr, a.robots) for _ in range(a.viewers)]
        print(f"{a.viewers} viewers subscribed to "
              f"{[n for _, n, _ in viewers]} channels each, then stopped reading")
        pinger = Pinger(addr, a.pings)
        pinger.start()
        # Client's port -> when it stopped reading (the pinger: began).
        stopped = {s.getsockname()[1]: t for s, _, t in viewers}
        stopped[pinger.sock.getsockname()[1]] = time.time()
        t0 = time.time()
        peak = base
        while time.time() - t0 < a.seconds:
            time.sleep(1)
            now = rss_kib(station.pid)
            peak = max(peak, now)
            s = int(time.time() - t0)
            if s % 5 == 0:
                print(f"  {s:3d} s  RSS {now / 1024:6.1f} MiB  pings taken {pinger.sent}")
        last = rss_kib(station.pid)
        pinger.stop = True
        print(f"baseline {base / 1024:.1f} MiB, peak {peak / 1024:.1f} MiB, "
              f"after {a.seconds} s {last / 1024:.1f} MiB; "
              f"pings taken {pinger.sent} of {a.pings}")
        logs = glob.glob(os.path.join(state, "mech", "mech-gcs.log*"))
        text = "".join(open(f).read() for f in logs)
        cut = [l for l in text.splitlines()
               if "Foxglove client cut" in l or "too slow" in l]
        print(f"clients cut: {len(cut)}")
        for l in cut:
            stamp = datetime.datetime.fromisoformat(l.split()[0].replace("Z", "+00:00"))
            port = int(l.split("peer=")[1].split()[0].rsplit(":", 1)[1])
            after = stamp.timestamp() - stopped.get(port, float("nan"))
            print(f"  {after:5.1f} s after it stopped reading: {l.strip()[:200]}")
    finally:
        station.kill()
        station.wait()


if __name__ == "__main__":
    main()
