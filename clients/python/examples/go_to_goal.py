"""Go to a goal: drives one robot to a point with a proportional controller
closed on its telemetry, publishing body twists on a channel at 20 Hz.

    python3 go_to_goal.py ROBOT X Y [--router HOST:PORT] [--channel ext/python]
                          [--key KEYFILE] [--tolerance 0.1] [--timeout 60]

Against `mech-gcs --demo` (router 127.0.0.1:7400, unsigned), route the robot
to the channel in the station first: `:route robot_1 ext/python`. Prints one
JSON line when done; exits 0 when the robot is within the tolerance, 1 when
the timeout passes first, 3 when it cannot steer: the station is not there,
or the robot's telemetry stayed stale for 3 s (it publishes stops while
telemetry is stale, and says so on stderr).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

from mech_client import Client, MechError, RouterUnreachable, StaleTelemetry, read_key

RATE_HZ = 20.0
MAX_SPEED = 0.3  # m/s
MAX_YAW_RATE = 1.2  # rad/s
K_POSITION = 1.0  # (m/s) per m of distance
K_HEADING = 2.5  # (rad/s) per rad of heading error
GIVE_UP_STALE = 3.0  # s of stale telemetry before giving up


def wrap(angle: float) -> float:
    """An angle in (-pi, pi]."""
    return math.atan2(math.sin(angle), math.cos(angle))


def twist_towards(x: float, y: float, heading: float, gx: float, gy: float) -> tuple:
    """The body twist (vx, wz) that turns towards the goal and drives at a
    speed proportional to the distance, slowing while misaligned (so it
    suits a differential drive as well as a holonomic robot)."""
    dx, dy = gx - x, gy - y
    distance = math.hypot(dx, dy)
    error = wrap(math.atan2(dy, dx) - heading)
    wz = max(-MAX_YAW_RATE, min(MAX_YAW_RATE, K_HEADING * error))
    alignment = math.cos(error) if abs(error) < 1.0 else 0.0
    vx = min(MAX_SPEED, K_POSITION * distance) * alignment
    return vx, wz


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("robot")
    ap.add_argument("x", type=float)
    ap.add_argument("y", type=float)
    ap.add_argument("--router", default="127.0.0.1:7400")
    ap.add_argument("--channel", default="ext/python")
    ap.add_argument("--key", help="key file from `mech-gcs keygen NAME` (signed station)")
    ap.add_argument("--name", default="go_to_goal", help="sender name when unsigned")
    ap.add_argument("--tolerance", type=float, default=0.1)
    ap.add_argument("--timeout", type=float, default=60.0)
    args = ap.parse_args()

    key = read_key(args.key) if args.key else None
    with Client(None if key else args.name, args.router, key=key, sync_clock=key is not None) as mech:
        try:
            return drive(mech, args)
        except RouterUnreachable as e:
            print(json.dumps({"robot": args.robot, "arrived": False, "error": str(e)}))
            return 3


def drive(mech: Client, args: argparse.Namespace) -> int:
    """The control loop at RATE_HZ: steer on fresh telemetry only."""
    mech.subscribe()
    try:
        mech.wait_telemetry(args.robot, timeout=10.0)
    except MechError as e:
        print(json.dumps({"robot": args.robot, "arrived": False, "error": str(e)}))
        return 3
    deadline = time.monotonic() + args.timeout
    hinted = False
    stale_since = None
    while time.monotonic() < deadline:
        mech.poll(1.0 / RATE_HZ)
        try:
            t = mech.fresh_telemetry(args.robot)
        except StaleTelemetry as e:
            # Not steering blind: hold the robot, say so, give up in time.
            mech.stop(args.robot, args.channel)
            if stale_since is None:
                stale_since = time.monotonic()
                print(f"go_to_goal: {e}; holding", file=sys.stderr)
            if time.monotonic() - stale_since > GIVE_UP_STALE:
                print(json.dumps({"robot": args.robot, "arrived": False, "error": str(e)}))
                return 3
            continue
        stale_since = None
        p = t.pose
        error = math.hypot(args.x - p.x, args.y - p.y)
        if t.channel != args.channel:
            if not hinted:
                print(
                    f"{args.robot} obeys {t.channel or 'none'!r}; route it to {args.channel} "
                    f"(in mech-gcs: :route {args.robot} {args.channel})",
                    file=sys.stderr,
                )
                hinted = True
        elif error <= args.tolerance:
            mech.stop(args.robot, args.channel)
            print(json.dumps({"robot": args.robot, "arrived": True, "x": p.x, "y": p.y, "error": error}))
            return 0
        else:
            vx, wz = twist_towards(p.x, p.y, p.heading, args.x, args.y)
            mech.twist(args.robot, args.channel, vx=vx, wz=wz)
    mech.stop(args.robot, args.channel)
    last = mech.telemetry.get(args.robot)
    print(json.dumps({"robot": args.robot, "arrived": False, "x": last and last.pose.x, "y": last and last.pose.y}))
    return 1


if __name__ == "__main__":
    sys.exit(main())
