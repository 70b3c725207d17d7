"""Leader and follower: the leader drives a circle, the follower keeps a
point a fixed distance behind it (in the leader's frame), both commanded
from this one program on one channel, closed on their telemetry at 20 Hz.

    python3 leader_follower.py LEADER FOLLOWER [--offset 0.6] [--seconds 30]
                               [--router HOST:PORT] [--channel ext/python]
                               [--key KEYFILE]

Against `mech-gcs --demo`, route both robots to the channel first:
`:route robot_1 ext/python` and `:route robot_2 ext/python`. Stops both
robots at the end and prints one JSON line: the follower's tracking error
(distance from its slot) over the second half of the run. Steers on fresh
telemetry only: while either robot's is stale both are held (said on
stderr); after 3 s of it, or with the station gone, it stops and exits 3.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import List

from mech_client import Client, MechError, RouterUnreachable, StaleTelemetry, read_key

RATE_HZ = 20.0
LEADER_SPEED = 0.15  # m/s
LEADER_YAW_RATE = 0.3  # rad/s: a circle of 0.5 m radius
MAX_SPEED = 0.45  # follower, m/s
MAX_YAW_RATE = 1.5  # follower, rad/s
K_POSITION = 1.2
K_HEADING = 3.0
GIVE_UP_STALE = 3.0  # s of stale telemetry before giving up


def wrap(angle: float) -> float:
    """An angle in (-pi, pi]."""
    return math.atan2(math.sin(angle), math.cos(angle))


def slot(lx: float, ly: float, lheading: float, offset: float) -> tuple:
    """The point ``offset`` metres behind the leader."""
    return lx - offset * math.cos(lheading), ly - offset * math.sin(lheading)


def follow(x: float, y: float, heading: float, tx: float, ty: float, feed_forward: float) -> tuple:
    """Follower twist (vx, wz): turn to the slot, drive at the leader's speed
    plus a term proportional to the distance, slowing while misaligned."""
    dx, dy = tx - x, ty - y
    distance = math.hypot(dx, dy)
    error = wrap(math.atan2(dy, dx) - heading)
    if distance < 0.05:
        return 0.0, 0.0
    wz = max(-MAX_YAW_RATE, min(MAX_YAW_RATE, K_HEADING * error))
    alignment = math.cos(error) if abs(error) < 1.2 else 0.0
    vx = min(MAX_SPEED, feed_forward + K_POSITION * distance) * alignment
    return vx, wz


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("leader")
    ap.add_argument("follower")
    ap.add_argument("--offset", type=float, default=0.6, help="metres behind the leader")
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--router", default="127.0.0.1:7400")
    ap.add_argument("--channel", default="ext/python")
    ap.add_argument("--key", help="key file from `mech-gcs keygen NAME` (signed station)")
    ap.add_argument("--name", default="leader_follower", help="sender name when unsigned")
    args = ap.parse_args()

    key = read_key(args.key) if args.key else None
    errors: List[float] = []
    with Client(None if key else args.name, args.router, key=key, sync_clock=key is not None) as mech:
        mech.subscribe()
        try:
            for robot in (args.leader, args.follower):
                mech.wait_telemetry(robot, timeout=10.0)
        except MechError as e:
            print(f"leader_follower: {e}", file=sys.stderr)
            return 1
        start = time.monotonic()
        stale_since = None
        try:
            while time.monotonic() - start < args.seconds:
                mech.poll(1.0 / RATE_HZ)
                try:
                    lead = mech.fresh_telemetry(args.leader)
                    fol = mech.fresh_telemetry(args.follower)
                except StaleTelemetry as e:
                    for robot in (args.leader, args.follower):
                        mech.stop(robot, args.channel)
                    if stale_since is None:
                        stale_since = time.monotonic()
                        print(f"leader_follower: {e}; holding both", file=sys.stderr)
                    if time.monotonic() - stale_since > GIVE_UP_STALE:
                        print(json.dumps({"error": str(e)}))
                        return 3
                    continue
                stale_since = None
                for t, robot in ((lead, args.leader), (fol, args.follower)):
                    if t.channel != args.channel:
                        print(f"route {robot} to {args.channel} (:route {robot} {args.channel})", file=sys.stderr)
                tx, ty = slot(lead.pose.x, lead.pose.y, lead.pose.heading, args.offset)
                vx, wz = follow(fol.pose.x, fol.pose.y, fol.pose.heading, tx, ty, LEADER_SPEED)
                mech.twist(args.leader, args.channel, vx=LEADER_SPEED, wz=LEADER_YAW_RATE)
                mech.twist(args.follower, args.channel, vx=vx, wz=wz)
                if time.monotonic() - start > args.seconds / 2:
                    errors.append(math.hypot(tx - fol.pose.x, ty - fol.pose.y))
            for robot in (args.leader, args.follower):
                mech.stop(robot, args.channel)
        except RouterUnreachable as e:
            print(json.dumps({"error": str(e)}))
            return 3
    summary = {
        "leader": args.leader,
        "follower": args.follower,
        "mean_error": sum(errors) / len(errors) if errors else None,
        "max_error": max(errors) if errors else None,
    }
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
