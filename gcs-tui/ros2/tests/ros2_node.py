"""A ROS 2 node made of Cyclone DDS alone (no ROS installation, no MECH
code): topics named as ROS 2 names them on DDS (`rt/robot_1/odom`), types
named as its IDL generator names them (`nav_msgs::msg::dds_::Odometry_`),
structs in the `.msg` field order. The tests drive it with one JSON
command per line on stdin; it answers each with one JSON line on stdout.

    {"op": "watch", "robots": ["robot_1"], "stamped": false}
    {"op": "state"}                      -> what it has received
    {"op": "drive", "robot": "robot_1", "vx": 0.3, "wz": 0.0}   (20 Hz until halt)
    {"op": "halt", "robot": "robot_1"}
    {"op": "goal", "robot": "robot_1", "x": 1.0, "y": 0.5, "frame": "map"}
    {"op": "estop"}
    {"op": "estop_call"}                 -> the /mech/estop service's answer
    {"op": "quit"}

Numbers may be given as "nan" or "inf".
"""
import json
import math
import sys
import threading
import time

from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from ros2_types import (RELIABLE, SENSOR, BatteryState, DiagnosticArray, Empty, Header, MarkerArray,
                        Odometry, Point, Pose, PoseStamped, Quaternion, TFMessage, TriggerRequest,
                        TriggerResponse, Twist, TwistStamped, Vector3, now_stamp, num, plain,
                        seconds)


dp = DomainParticipant(0)
lock = threading.Lock()
readers = []          # (kind, key, reader)
writers = {}          # topic name -> writer
drivers = {}          # robot -> stop event
state = {"odom": {}, "tf": {}, "battery": {}, "diagnostics": {}, "markers": {}}
stamped = False


def reader(kind, key, topic, typ, qos):
    readers.append((kind, key, DataReader(dp, Topic(dp, topic, typ), qos=qos)))


def writer(topic, typ, qos):
    if topic not in writers:
        writers[topic] = DataWriter(dp, Topic(dp, topic, typ), qos=qos)
    return writers[topic]


def on_sample(kind, key, s, received):
    if kind == "odom":
        p, q, tw = s.pose.pose.position, s.pose.pose.orientation, s.twist.twist
        old = state["odom"].get(key, {})
        state["odom"][key] = {
            "frame_id": s.header.frame_id, "child_frame_id": s.child_frame_id,
            "x": p.x, "y": p.y, "z": p.z,
            "yaw": math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z)),
            "q_norm": math.sqrt(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2),
            "vx": tw.linear.x, "vy": tw.linear.y, "wz": tw.angular.z,
            "covariance_len": len(s.pose.covariance),
            "stamp": seconds(s.header.stamp), "received": received,
            "count": old.get("count", 0) + 1,
            "latency_ms": (received - seconds(s.header.stamp)) * 1e3,
        }
    elif kind == "tf":
        for t in s.transforms:
            old = state["tf"].get(t.child_frame_id, {})
            state["tf"][t.child_frame_id] = {
                "parent": t.header.frame_id, "x": t.transform.translation.x,
                "y": t.transform.translation.y, "count": old.get("count", 0) + 1,
            }
    elif kind == "battery":
        state["battery"][key] = {"percentage": s.percentage, "present": s.present,
                                 "frame_id": s.header.frame_id,
                                 "voltage_is_nan": math.isnan(s.voltage)}
    elif kind == "diagnostics":
        for st in s.status:
            state["diagnostics"][st.name] = {
                "level": st.level, "message": st.message, "hardware_id": st.hardware_id,
                "values": {kv.key: kv.value for kv in st.values},
            }
    elif kind == "markers":
        for m in s.markers:
            state["markers"][f"{m.ns}/{m.id}"] = {
                "type": m.type, "action": m.action, "text": m.text,
                "x": m.pose.position.x, "y": m.pose.position.y, "frame_id": m.header.frame_id,
            }


def poll():
    while True:
        with lock:
            for kind, key, r in list(readers):
                for s in r.take(N=256):
                    on_sample(kind, key, s, time.time())
        time.sleep(0.005)


def twist_of(cmd):
    return Twist(linear=Vector3(x=num(cmd.get("vx", 0.0)), y=num(cmd.get("vy", 0.0))),
                 angular=Vector3(x=num(cmd.get("wx", 0.0)), z=num(cmd.get("wz", 0.0))))


def cmd_vel(cmd):
    robot = cmd["robot"]
    if stamped:
        w = writer(f"rt/{robot}/cmd_vel", TwistStamped, RELIABLE)
        msg = TwistStamped(header=Header(stamp=now_stamp(), frame_id=cmd.get("frame", "")),
                           twist=twist_of(cmd))
    else:
        w = writer(f"rt/{robot}/cmd_vel", Twist, RELIABLE)
        msg = twist_of(cmd)
    return w, msg


def drive(cmd):
    halt(cmd)
    stop = threading.Event()
    drivers[cmd["robot"]] = stop

    def run():
        while not stop.is_set():
            with lock:
                w, msg = cmd_vel(cmd)
                w.write(msg)
            stop.wait(0.05)
    threading.Thread(target=run, daemon=True).start()


def halt(cmd):
    stop = drivers.pop(cmd["robot"], None)
    if stop is not None:
        stop.set()


def estop_call():
    """Calls /mech/estop (std_srvs/Trigger) as rmw_cyclonedds maps a
    service: request on rq/mech/estopRequest, reply on rr/mech/estopReply,
    matched by sequence number. Asks again every 0.5 s until answered."""
    with lock:
        w = writer("rq/mech/estopRequest", TriggerRequest, RELIABLE)
        if "estop_reply" not in writers:
            writers["estop_reply"] = DataReader(
                dp, Topic(dp, "rr/mech/estopReply", TriggerResponse), qos=RELIABLE)
    replies = writers["estop_reply"]
    guid = [7, 7, 7, 7, 7, 7, 7, 7]
    deadline = time.time() + 20
    seq = 0
    while time.time() < deadline:
        seq += 1
        with lock:
            w.write(TriggerRequest(guid=guid, seq_high=0, seq_low=seq))
        until = time.time() + 0.5
        while time.time() < until:
            for r in replies.take(N=16):
                if list(r.guid) == guid and r.seq_low <= seq:
                    return {"success": r.success, "message": r.message, "calls": seq}
            time.sleep(0.01)
    return {"error": "no answer from /mech/estop"}


def handle(cmd):
    global stamped
    op = cmd["op"]
    if op == "watch":
        stamped = cmd.get("stamped", False)
        with lock:
            for r in cmd["robots"]:
                reader("odom", r, f"rt/{r}/odom", Odometry, SENSOR)
                reader("battery", r, f"rt/{r}/battery", BatteryState, RELIABLE)
            reader("tf", None, "rt/tf", TFMessage, RELIABLE)
            reader("diagnostics", None, "rt/diagnostics", DiagnosticArray, RELIABLE)
            reader("markers", None, "rt/mech/markers", MarkerArray, RELIABLE)
            writer("rt/mech/estop", Empty, RELIABLE)
        return {"ok": True}
    if op == "state":
        with lock:
            return plain(state)
    if op == "drive":
        drive(cmd)
        return {"ok": True}
    if op == "halt":
        halt(cmd)
        return {"ok": True}
    if op == "goal":
        with lock:
            w = writer(f"rt/{cmd['robot']}/goal_pose", PoseStamped, RELIABLE)
            yaw = num(cmd.get("yaw", 0.0))
            w.write(PoseStamped(
                header=Header(stamp=now_stamp(), frame_id=cmd.get("frame", "map")),
                pose=Pose(position=Point(x=num(cmd["x"]), y=num(cmd["y"])),
                          orientation=Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2)))))
        return {"ok": True}
    if op == "estop":
        with lock:
            writers["rt/mech/estop"].write(Empty())
        return {"ok": True}
    if op == "estop_call":
        return estop_call()
    if op == "quit":
        return None
    return {"error": f"unknown op {op}"}


threading.Thread(target=poll, daemon=True).start()
print(json.dumps({"ready": True}), flush=True)
for line in sys.stdin:
    if not line.strip():
        continue
    answer = handle(json.loads(line))
    if answer is None:
        break
    print(json.dumps(answer), flush=True)
