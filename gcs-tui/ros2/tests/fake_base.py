"""A fake ROS 2 mobile base made of Cyclone DDS alone (no ROS installation,
no MECH code), for the tests of the agent's ROS 2 platform: a differential
drive that obeys the last `cmd_vel` it received and publishes its odometry
and battery, under ROS 2's topic and type names (`ros2_types.py`).

- subscribes to `<ns>/cmd_vel`, geometry_msgs/Twist (or TwistStamped with
  `--stamped`), reliable as a TurtleBot's node asks (`--cmd-vel-qos`);
- integrates the last command exactly (an arc), its speed and turn rate
  clamped to its own limits. A command does not expire: a base that keeps
  going on its last command (the agent's stream of zeros is what stops it);
  `--cmd-timeout S` makes a command older than S count as zero instead;
- publishes nav_msgs/Odometry on `<ns>/odom` at `--odom-hz` (frame
  `odom`, child `base_link`, pose in `odom`, twist in the body frame),
  reliable or best effort (`--odom-qos`), and sensor_msgs/BatteryState on
  `<ns>/battery_state` once a second;
- with `--map X,Y,YAW`, publishes `map` -> `odom` (where a localiser such
  as AMCL puts the odometry's frame in the map) on `/tf` 10 times a second.

Its true pose is what the tests measure against. One JSON command per line
on stdin, one JSON answer per line on stdout (the first line says it is
ready; times are wall-clock seconds, `time.time()`):

    {"op": "state"}     -> true pose and velocity, the last cmd_vel, how many
                           cmd_vel samples and distinct writers it has heard
    {"op": "cmds", "since": T}    -> cmd_vel samples received after T:
                           [t, vx, wz, writer], writer 0 the first heard
    {"op": "track", "since": T}   -> true poses after T: [t, x, y, yaw]
    {"op": "nan", "on": true, "field": "x"}   NaN in odometry ("x", "yaw", "vx")
    {"op": "silence", "on": true}             no odometry while on
    {"op": "intruder", "vx": 0.1, "wz": 0.0}  a second node publishing on
                           cmd_vel at 10 Hz, a DDS participant of its own
    {"op": "intruder_stop"}
    {"op": "quit"}

    python3 fake_base.py --namespace /tb3_1 --x 0.5 --y 0.4 --yaw 0.0
"""
import argparse
import collections
import json
import math
import os
import sys
import threading
import time

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from ros2_types import (BatteryState, Header, Odometry, Point, Pose, PoseWithCovariance,
                        Quaternion, TFMessage, Transform, TransformStamped, Twist, TwistStamped,
                        TwistWithCovariance, Vector3, now_stamp, plain)

NAN = float("nan")
PHYSICS_HZ = 100.0
# About two minutes of samples at the rates here.
HISTORY = 12_000


def qos(kind):
    if kind == "best-effort":
        return Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(10))
    return Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))


def topic_name(namespace, name):
    ns = namespace.strip("/")
    return f"rt/{ns}/{name}" if ns else f"rt/{name}"


def arguments():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--namespace", default="")
    p.add_argument("--domain", type=int, default=int(os.environ.get("ROS_DOMAIN_ID") or 0))
    p.add_argument("--stamped", action="store_true", help="cmd_vel is TwistStamped")
    p.add_argument("--cmd-vel-qos", choices=["reliable", "best-effort"], default="reliable")
    p.add_argument("--odom-qos", choices=["reliable", "best-effort"], default="reliable")
    p.add_argument("--odom-hz", type=float, default=30.0)
    p.add_argument("--max-speed", type=float, default=0.22, help="m/s (a TurtleBot 3 Burger's)")
    p.add_argument("--max-yaw-rate", type=float, default=2.84, help="rad/s")
    p.add_argument("--cmd-timeout", type=float, default=0.0,
                   help="s after which a command counts as zero (0: never)")
    p.add_argument("--battery", type=float, default=0.8, help="fraction, 0 to 1")
    p.add_argument("--x", type=float, default=0.0, help="start pose in the odom frame, m")
    p.add_argument("--y", type=float, default=0.0)
    p.add_argument("--yaw", type=float, default=0.0, help="rad")
    p.add_argument("--map", default="", help="X,Y,YAW: map -> odom on /tf")
    return p.parse_args()


class Base:
    """The vehicle and its DDS endpoints; `lock` guards everything here."""

    def __init__(self, args):
        self.args = args
        self.lock = threading.Lock()
        self.x, self.y, self.yaw = args.x, args.y, args.yaw
        self.v = self.w = 0.0
        self.cmd = None            # {"t", "vx", "wz", "frame", "writer"}
        self.cmd_count = 0
        self.writers = {}          # publication handle -> index
        self.cmds = collections.deque(maxlen=HISTORY)
        self.track = collections.deque(maxlen=HISTORY)
        self.odom_count = 0
        self.nan = None            # the odometry field published as NaN
        self.silent = False
        self.intruder = None       # (participant, thread, stop event)
        self.dp = DomainParticipant(args.domain)
        self.cmd_type = TwistStamped if args.stamped else Twist
        self.cmd_topic = topic_name(args.namespace, "cmd_vel")
        self.cmd_reader = DataReader(
            self.dp, Topic(self.dp, self.cmd_topic, self.cmd_type), qos=qos(args.cmd_vel_qos))
        self.odom_writer = DataWriter(
            self.dp, Topic(self.dp, topic_name(args.namespace, "odom"), Odometry),
            qos=qos(args.odom_qos))
        self.battery_writer = DataWriter(
            self.dp, Topic(self.dp, topic_name(args.namespace, "battery_state"), BatteryState),
            qos=qos("reliable"))
        self.map = [float(v) for v in args.map.split(",")] if args.map else None
        self.tf_writer = DataWriter(self.dp, Topic(self.dp, "rt/tf", TFMessage),
                                    qos=qos("reliable")) if self.map else None

    def map_to_odom(self):
        x, y, yaw = self.map
        return TFMessage(transforms=[TransformStamped(
            header=Header(stamp=now_stamp(), frame_id="map"), child_frame_id="odom",
            transform=Transform(translation=Vector3(x=x, y=y),
                                rotation=Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2))))])

    def receive(self, now):
        for s in self.cmd_reader.take(N=64):
            info = getattr(s, "sample_info", None)
            if s is None or (info is not None and not info.valid_data):
                continue
            handle = info.publication_handle if info is not None else 0
            writer = self.writers.setdefault(handle, len(self.writers))
            twist = s.twist if self.args.stamped else s
            frame = s.header.frame_id if self.args.stamped else None
            self.cmd = {"t": now, "vx": twist.linear.x, "wz": twist.angular.z, "frame": frame,
                        "writer": writer}
            self.cmd_count += 1
            self.cmds.append([now, twist.linear.x, twist.angular.z, writer])

    def commanded(self, now):
        """The speed and turn rate the base drives at: the last command,
        clamped (a NaN or stale command is zero)."""
        c = self.cmd
        if c is None:
            return 0.0, 0.0
        if self.args.cmd_timeout > 0 and now - c["t"] > self.args.cmd_timeout:
            return 0.0, 0.0
        v, w = c["vx"], c["wz"]
        if not (math.isfinite(v) and math.isfinite(w)):
            return 0.0, 0.0
        return clamp(v, self.args.max_speed), clamp(w, self.args.max_yaw_rate)

    def step(self, dt, now):
        self.v, self.w = self.commanded(now)
        v, w, th = self.v, self.w, self.yaw
        if abs(w) < 1e-9:
            self.x += v * dt * math.cos(th)
            self.y += v * dt * math.sin(th)
        else:
            self.x += v / w * (math.sin(th + w * dt) - math.sin(th))
            self.y -= v / w * (math.cos(th + w * dt) - math.cos(th))
        self.yaw = math.atan2(math.sin(th + w * dt), math.cos(th + w * dt))

    def odometry(self):
        x, y, yaw, vx = self.x, self.y, self.yaw, self.v
        if self.nan == "x":
            x = NAN
        elif self.nan == "yaw":
            yaw = NAN
        elif self.nan == "vx":
            vx = NAN
        return Odometry(
            header=Header(stamp=now_stamp(), frame_id="odom"),
            child_frame_id="base_link",
            pose=PoseWithCovariance(pose=Pose(
                position=Point(x=x, y=y),
                orientation=Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2)))),
            twist=TwistWithCovariance(twist=Twist(linear=Vector3(x=vx),
                                                  angular=Vector3(z=self.w))))

    def battery(self):
        # Unknown quantities are NaN, as sensor_msgs/BatteryState says.
        return BatteryState(header=Header(stamp=now_stamp(), frame_id="base_link"),
                            voltage=11.1, current=NAN, charge=NAN, capacity=NAN,
                            design_capacity=NAN, temperature=NAN,
                            percentage=self.args.battery, present=True,
                            power_supply_status=2)  # discharging

    def run(self):
        """Physics at PHYSICS_HZ, odometry at the asked rate, map -> odom at
        10 Hz, battery at 1 Hz."""
        period = 1.0 / PHYSICS_HZ
        odom_every = 1.0 / self.args.odom_hz
        last = time.time()
        next_odom = next_battery = next_tf = last
        while True:
            now = time.time()
            with self.lock:
                self.receive(now)
                self.step(now - last, now)
                last = now
                if now >= next_odom:
                    next_odom = max(next_odom + odom_every, now)
                    self.track.append([now, self.x, self.y, self.yaw])
                    if not self.silent:
                        self.odom_writer.write(self.odometry())
                        self.odom_count += 1
                if now >= next_battery:
                    next_battery += 1.0
                    self.battery_writer.write(self.battery())
                if self.tf_writer is not None and now >= next_tf:
                    next_tf += 0.1
                    self.tf_writer.write(self.map_to_odom())
            time.sleep(max(0.0, period - (time.time() - now)))

    def start_intruder(self, vx, wz):
        """Another node on the same cmd_vel: a participant of its own, as a
        teleop or a second driver started by mistake would be."""
        self.stop_intruder()
        dp = DomainParticipant(self.args.domain)
        writer = DataWriter(dp, Topic(dp, self.cmd_topic, self.cmd_type), qos=qos("reliable"))
        stop = threading.Event()
        twist = Twist(linear=Vector3(x=vx), angular=Vector3(z=wz))

        def run():
            while not stop.is_set():
                if self.args.stamped:
                    writer.write(TwistStamped(header=Header(stamp=now_stamp(), frame_id="base_link"),
                                              twist=twist))
                else:
                    writer.write(twist)
                stop.wait(0.1)

        thread = threading.Thread(target=run, daemon=True)
        thread.start()
        self.intruder = (dp, thread, stop)

    def stop_intruder(self):
        if self.intruder is not None:
            _, thread, stop = self.intruder
            stop.set()
            thread.join()
            # The participant and its writer go with their last reference.
            self.intruder = None

    def state(self):
        return {
            "t": time.time(), "x": self.x, "y": self.y, "yaw": self.yaw, "v": self.v,
            "w": self.w, "cmd": self.cmd, "cmd_count": self.cmd_count,
            "cmd_writers": len(self.writers),
            "cmd_writers_matched": self.cmd_reader.get_subscription_matched_status().current_count,
            "odom_count": self.odom_count, "nan": self.nan, "silent": self.silent,
            "intruder": self.intruder is not None,
        }


def clamp(a, limit):
    return max(-limit, min(limit, a))


def handle(base, cmd):
    op = cmd["op"]
    since = float(cmd.get("since", 0.0))
    if op == "intruder":
        base.start_intruder(float(cmd.get("vx", 0.1)), float(cmd.get("wz", 0.0)))
        return {"ok": True}
    if op == "intruder_stop":
        base.stop_intruder()
        return {"ok": True}
    with base.lock:
        if op == "state":
            return base.state()
        if op == "cmds":
            return {"cmds": [c for c in base.cmds if c[0] > since]}
        if op == "track":
            return {"track": [p for p in base.track if p[0] > since]}
        if op == "nan":
            base.nan = cmd.get("field", "x") if cmd.get("on", True) else None
            return {"ok": True}
        if op == "silence":
            base.silent = bool(cmd.get("on", True))
            return {"ok": True}
    return {"error": f"unknown op {op}"}


def main():
    base = Base(arguments())
    threading.Thread(target=base.run, daemon=True).start()
    print(json.dumps({"ready": True, "cmd_vel": base.cmd_topic}), flush=True)
    for line in sys.stdin:
        if not line.strip():
            continue
        cmd = json.loads(line)
        if cmd["op"] == "quit":
            break
        print(json.dumps(plain(handle(base, cmd))), flush=True)
    base.stop_intruder()
    return 0


if __name__ == "__main__":
    sys.exit(main())
