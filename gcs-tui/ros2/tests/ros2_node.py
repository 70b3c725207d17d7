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
from dataclasses import dataclass, field
from typing import List

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Duration(IdlStruct, typename="builtin_interfaces::msg::dds_::Duration_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class Empty(IdlStruct, typename="std_msgs::msg::dds_::Empty_"):
    structure_needs_at_least_one_member: uint8 = 0


@dataclass
class ColorRGBA(IdlStruct, typename="std_msgs::msg::dds_::ColorRGBA_"):
    r: float32 = 0.0
    g: float32 = 0.0
    b: float32 = 0.0
    a: float32 = 0.0


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose = field(default_factory=Pose)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist = field(default_factory=Twist)
    covariance: array[float64, 36] = field(default_factory=lambda: [0.0] * 36)


@dataclass
class TwistStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TwistStamped_"):
    header: Header = field(default_factory=Header)
    twist: Twist = field(default_factory=Twist)


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass
class Odometry(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
    twist: TwistWithCovariance = field(default_factory=TwistWithCovariance)


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped] = field(default_factory=list)


@dataclass
class BatteryState(IdlStruct, typename="sensor_msgs::msg::dds_::BatteryState_"):
    header: Header = field(default_factory=Header)
    voltage: float32 = 0.0
    temperature: float32 = 0.0
    current: float32 = 0.0
    charge: float32 = 0.0
    capacity: float32 = 0.0
    design_capacity: float32 = 0.0
    percentage: float32 = 0.0
    power_supply_status: uint8 = 0
    power_supply_health: uint8 = 0
    power_supply_technology: uint8 = 0
    present: bool = False
    cell_voltage: sequence[float32] = field(default_factory=list)
    cell_temperature: sequence[float32] = field(default_factory=list)
    location: str = ""
    serial_number: str = ""


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str = ""
    value: str = ""


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8 = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header = field(default_factory=Header)
    status: sequence[DiagnosticStatus] = field(default_factory=list)


@dataclass
class CompressedImage(IdlStruct, typename="sensor_msgs::msg::dds_::CompressedImage_"):
    header: Header = field(default_factory=Header)
    format: str = ""
    data: sequence[uint8] = field(default_factory=list)


@dataclass
class UVCoordinate(IdlStruct, typename="visualization_msgs::msg::dds_::UVCoordinate_"):
    u: float32 = 0.0
    v: float32 = 0.0


@dataclass
class MeshFile(IdlStruct, typename="visualization_msgs::msg::dds_::MeshFile_"):
    filename: str = ""
    data: sequence[uint8] = field(default_factory=list)


@dataclass
class Marker(IdlStruct, typename="visualization_msgs::msg::dds_::Marker_"):
    header: Header = field(default_factory=Header)
    ns: str = ""
    id: int32 = 0
    type: int32 = 0
    action: int32 = 0
    pose: Pose = field(default_factory=Pose)
    scale: Vector3 = field(default_factory=Vector3)
    color: ColorRGBA = field(default_factory=ColorRGBA)
    lifetime: Duration = field(default_factory=Duration)
    frame_locked: bool = False
    points: sequence[Point] = field(default_factory=list)
    colors: sequence[ColorRGBA] = field(default_factory=list)
    texture_resource: str = ""
    texture: CompressedImage = field(default_factory=CompressedImage)
    uv_coordinates: sequence[UVCoordinate] = field(default_factory=list)
    text: str = ""
    mesh_resource: str = ""
    mesh_file: MeshFile = field(default_factory=MeshFile)
    mesh_use_embedded_materials: bool = False


@dataclass
class MarkerArray(IdlStruct, typename="visualization_msgs::msg::dds_::MarkerArray_"):
    markers: sequence[Marker] = field(default_factory=list)


@dataclass
class TriggerRequest(IdlStruct, typename="std_srvs::srv::dds_::Trigger_Request_"):
    """As rmw_cyclonedds sends a request: its header (the client's GUID's
    last 8 bytes, a sequence number), then the request."""
    guid: array[uint8, 8] = field(default_factory=lambda: [0] * 8)
    seq_high: int32 = 0
    seq_low: uint32 = 0
    structure_needs_at_least_one_member: uint8 = 0


@dataclass
class TriggerResponse(IdlStruct, typename="std_srvs::srv::dds_::Trigger_Response_"):
    guid: array[uint8, 8] = field(default_factory=lambda: [0] * 8)
    seq_high: int32 = 0
    seq_low: uint32 = 0
    success: bool = False
    message: str = ""


SENSOR = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5))
RELIABLE = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))

dp = DomainParticipant(0)
lock = threading.Lock()
readers = []          # (kind, key, reader)
writers = {}          # topic name -> writer
drivers = {}          # robot -> stop event
state = {"odom": {}, "tf": {}, "battery": {}, "diagnostics": {}, "markers": {}}
stamped = False


def plain(v):
    """JSON without NaN or infinities (which JSON lacks): null instead."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: plain(x) for k, x in v.items()}
    if isinstance(v, list):
        return [plain(x) for x in v]
    return v


def num(v):
    return float(v) if isinstance(v, str) else v


def now_stamp():
    t = time.time()
    return Time(sec=int(t), nanosec=int((t % 1) * 1e9))


def seconds(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


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
