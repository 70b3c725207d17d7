#!/usr/bin/env python3
"""Attach to a running MECH station (`mech-gcs serve`), run command-language
lines, and read the fleet.

    python3 attach.py SOCKET [LINE...]
    python3 attach.py --tcp HOST:PORT --key OPERATOR.key [LINE...]

Prints one line per robot of the first fleet snapshot, then each LINE's
result. Standard library only: the attach protocol is JSON lines
(docs/control-protocol.md).
"""

import hashlib
import hmac
import json
import re
import socket
import struct
import sys


def attach_tag(secret: bytes, nonce: bytes, name: str) -> bytes:
    key_id = hashlib.sha256(secret).digest()[:4]
    head = key_id + bytes([0]) + struct.pack(">Q", 0)
    region = b"mech-attach/1\0" + nonce + b"\0" + name.encode()
    return head + hmac.new(secret, region + head, hashlib.sha256).digest()[:16]


def read_key(path):
    """(name, secret) of a key file written by `mech-gcs keygen`."""
    text = open(path).read()
    name = re.search(r'^name\s*=\s*"([^"]*)"', text, re.M).group(1)
    secret = re.search(r'^secret\s*=\s*"([0-9a-fA-F]{64})"', text, re.M).group(1)
    return name, bytes.fromhex(secret)


class Station:
    def __init__(self, address, key=None, operator="python"):
        if key is None:
            self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            self.sock.connect(address)
        else:
            host, port = address.rsplit(":", 1)
            self.sock = socket.create_connection((host, int(port)))
            operator = key[0]
        self.file = self.sock.makefile("rwb")
        self.send({"type": "hello", "protocol": 1, "operator": operator,
                   "stream": {"snapshots": True}})
        answer = self.recv()
        if answer["type"] == "challenge" and key is not None:
            tag = attach_tag(key[1], bytes.fromhex(answer["nonce"]), key[0])
            self.send({"type": "auth", "tag": tag.hex()})
            answer = self.recv()
        if answer["type"] != "welcome":
            raise SystemExit(f"refused: {answer}")
        self.welcome = answer
        self.next_id = 0

    def send(self, message):
        self.file.write(json.dumps(message).encode() + b"\n")
        self.file.flush()

    def recv(self):
        line = self.file.readline()
        if not line:
            raise SystemExit("the station closed the connection")
        return json.loads(line)

    def snapshot(self):
        """The next fleet snapshot."""
        while True:
            m = self.recv()
            if m["type"] == "snapshot":
                return m["fleet"]

    def run(self, text):
        """Runs one command line; returns its result."""
        self.next_id += 1
        self.send({"type": "line", "id": self.next_id, "text": text})
        while True:
            m = self.recv()
            if m["type"] == "result" and m["id"] == self.next_id:
                return m


def main():
    args = sys.argv[1:]
    if args[:1] == ["--tcp"] and len(args) >= 4 and args[2] == "--key":
        station = Station(args[1], key=read_key(args[3]))
        lines = args[4:]
    elif args:
        station = Station(args[0])
        lines = args[1:]
    else:
        raise SystemExit(__doc__)
    print(f"attached as {station.welcome['operator']} to {station.welcome['router']}")
    for r in station.snapshot()["robots"]:
        x, y = r["pose"]["x"], r["pose"]["y"]
        route = r["route"]["channel"] or "none"
        print(f"{r['name']} {r['platform']} {r['link']} at ({x:.2f}, {y:.2f}) route {route}")
    ok = True
    for line in lines:
        result = station.run(line)
        ok = ok and result["ok"]
        print(f"{line}: {result.get('summary') or result.get('error')}")
    station.send({"type": "bye"})
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
