"""A MECH controller in 30 lines: drives robot_1 forward on channel
ext/python, signing every message with its key (docs/protocol.md).

    python3 controller.py KEYFILE [ROUTER_HOST:PORT] [SECONDS]
"""
import hashlib, hmac, socket, struct, sys, time
import msgpack  # pip install msgpack

def read_key(path):                                    # a key file from `mech-gcs keygen`
    pairs = (l.split("=", 1) for l in open(path) if "=" in l and not l.startswith("#"))
    fields = {k.strip(): v.strip().strip('"') for k, v in pairs}
    return bytes.fromhex(fields["secret"]), fields["name"]

def sign(region, secret, stamp_us, link=0):
    key_id = hashlib.sha256(secret).digest()[:4]
    head = key_id + bytes([link]) + struct.pack(">Q", stamp_us)
    mac = hmac.new(secret, region + head, hashlib.sha256).digest()[:16]
    return region + b"\xc4\x1d" + head + mac   # auth = bin 8 of 29 bytes

secret, name = read_key(sys.argv[1])
host, port = (sys.argv[2] if len(sys.argv) > 2 else "127.0.0.1:7400").rsplit(":", 1)
seconds = float(sys.argv[3]) if len(sys.argv) > 3 else 10.0
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
seq, last = 0, 0
end = time.time() + seconds
while time.time() < end:
    seq += 1
    stamp = max(int(time.time() * 1e6), last + 1)     # station time, rising
    last = stamp
    twist = [4, [0.3, 0.0, 0.0, 0.2]]                 # Command: Twist
    msg = [1, 5, seq, stamp, name, "robot_1", "ext/python", twist, None]
    region = msgpack.packb(msg)[:-1]                  # drop the nil auth element
    sock.sendto(sign(region, secret, stamp), (host, int(port)))
    time.sleep(0.05)                                   # 20 Hz keeps the failsafe quiet
