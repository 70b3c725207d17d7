"""The MECH wire format (docs/protocol.md): envelopes, bodies and commands
as plain Python values, encoded to and decoded from MessagePack exactly as
the reference implementation (the Rust crate ``mech-proto``) does.

Every message is a nine-element array: version, kind, seq, stamp_us,
sender, destination, channel, body, auth. Bodies are arrays of their fields
in order; enums are small integers; real numbers travel as float64.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Dict, List, Optional, Sequence, Tuple

import msgpack

VERSION = 1
"""Protocol version this package speaks."""

MAX_MESSAGE_LEN = 60_000
"""Largest message in bytes (one UDP datagram)."""

MAX_NAME_LEN = 64
"""Longest robot, sender or channel name, in UTF-8 bytes."""

ROUTER = "router"
"""Destination of messages for the router itself."""

BROADCAST = "*"
"""Destination meaning every robot."""


class Kind(IntEnum):
    """Body kinds: the envelope's ``kind`` field."""

    HELLO = 1
    WELCOME = 2
    HEARTBEAT = 3
    TELEMETRY = 4
    COMMAND = 5
    FLEET_COMMAND = 6
    MISSION = 7
    MISSION_ACK = 8
    ROUTE = 9
    ROUTE_ACK = 10
    ESTOP = 11
    ESTOP_ACK = 12
    CHANNELS_REQUEST = 13
    CHANNELS = 14
    CLUSTER = 15
    NOTICE = 16
    SUBSCRIBE = 17
    POSITION_FIX = 18
    BYE = 19
    TIME_REQUEST = 20
    TIME = 21
    AUTOPILOT = 22


class CommandKind(IntEnum):
    """Command kinds (and robot capabilities; 5 = accepts missions)."""

    ACTUATORS = 1
    STEERING_THROTTLE = 2
    VELOCITY_HEADING = 3
    TWIST = 4
    WAYPOINTS = 5
    STOP = 6


class ControlMode(IntEnum):
    """What a robot does with its actuators (telemetry ``mode``)."""

    IDLE = 0
    ACTUATORS = 1
    STEERING_THROTTLE = 2
    VELOCITY_HEADING = 3
    TWIST = 4
    WAYPOINTS = 5
    STOPPED = 6


class FailsafeState(IntEnum):
    """Why a robot holds its actuators at zero, if it does."""

    OK = 0
    CHANNEL_SILENT = 1
    ROUTER_LOST = 2
    ESTOPPED = 3
    FAULT = 4


class Health(IntEnum):
    """The robot's own judgement of its health."""

    OK = 0
    DEGRADED = 1
    FAULT = 2


class Level(IntEnum):
    """Severity of a notice."""

    DEBUG = 0
    INFO = 1
    WARN = 2
    ERROR = 3


class AutopilotAction(IntEnum):
    """What an operator asks a robot's autopilot to do (docs/autopilots.md)."""

    DISARM = 0
    ARM = 1
    OFFBOARD = 2
    HOLD = 3
    LAND = 4
    TAKEOFF = 5


class ProtocolError(ValueError):
    """Bytes that are not a valid MECH message (or a value that cannot be
    sent as one)."""


# ----------------------------------------------------------------- commands

Command = Tuple[int, List[Any]]
"""A command as it travels: ``(command kind, payload fields)``."""


def _real(value: float, what: str) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ProtocolError(f"{what} is not a finite number")
    return v


MAX_WAYPOINT_TIME = 86_400.0
"""Latest arrival time a waypoint may ask for, s after its mission starts."""


def _arrival(value: float) -> float:
    v = _real(value, "waypoint time")
    if not 0.0 <= v <= MAX_WAYPOINT_TIME:
        raise ProtocolError(f"waypoint time {v} s is not within 0..{MAX_WAYPOINT_TIME:.0f} s")
    return v


def twist(vx: float = 0.0, vy: float = 0.0, vz: float = 0.0, wz: float = 0.0) -> Command:
    """Body-frame velocity (REP 103: x forward, y left, z up), m/s, and yaw
    rate ``wz`` in rad/s, counter-clockwise positive."""
    return (
        CommandKind.TWIST,
        [_real(vx, "vx"), _real(vy, "vy"), _real(vz, "vz"), _real(wz, "wz")],
    )


def velocity_heading(speed: float, heading: float) -> Command:
    """Drive at ``speed`` m/s (negative reverses) holding the world-frame
    ``heading`` (rad, counter-clockwise from +x)."""
    return (CommandKind.VELOCITY_HEADING, [_real(speed, "speed"), _real(heading, "heading")])


def steering_throttle(steering: float, throttle: float) -> Command:
    """Car-style input, both in [-1, 1]; steering > 0 turns left."""
    s, t = _real(steering, "steering"), _real(throttle, "throttle")
    if not (-1.0 <= s <= 1.0 and -1.0 <= t <= 1.0):
        raise ProtocolError("steering and throttle must lie in [-1, 1]")
    return (CommandKind.STEERING_THROTTLE, [s, t])


def actuators(outputs: Sequence[float]) -> Command:
    """One output per motor, each in [-1, 1], at most 32."""
    values = [_real(o, "actuator output") for o in outputs]
    if len(values) > 32 or any(not -1.0 <= o <= 1.0 for o in values):
        raise ProtocolError("at most 32 actuator outputs, each in [-1, 1]")
    return (CommandKind.ACTUATORS, [values])


def stop() -> Command:
    """A controlled stop (not latched: the next command moves again)."""
    return (CommandKind.STOP, [])


# ------------------------------------------------------------------ bodies


@dataclass
class Pose:
    """Position (m) and heading (rad, CCW from +x) in the world frame."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    heading: float = 0.0


@dataclass
class Velocity:
    """World-frame velocity (m/s) and yaw rate (rad/s)."""

    vx: float = 0.0
    vy: float = 0.0
    vz: float = 0.0
    wz: float = 0.0


@dataclass
class MissionProgress:
    """The mission a robot holds: id, next waypoint index, waypoint count."""

    id: int
    next: int
    total: int


@dataclass
class Telemetry:
    """A robot's state, as it reports it at its telemetry rate."""

    pose: Pose
    velocity: Velocity
    mode: ControlMode
    channel: str
    offboard: bool
    failsafe: FailsafeState
    health: Health
    battery: Optional[float]
    position_quality: float
    actuators: List[float]
    mission: Optional[MissionProgress]
    stale: int = 0
    # True when wheel encoders measured `velocity`; False when it follows
    # from the commanded outputs.
    measured: bool = False
    # The robot's safety layer (docs/safety.md), from robots that have one.
    safety: Optional["SafetyReport"] = None


# What a robot's safety layer does to a command (docs/safety.md), by number.
INTERVENTIONS = ("none", "fence", "keep_out", "separation", "stale_neighbours", "slow_zone", "returning")
SAFETY_STATES = ("no_arena", "on", "off")


@dataclass
class SafetyReport:
    """A robot's safety layer as its telemetry reports it: `state`
    (no_arena, on, off: off is an operator's alarm), the arena id in force,
    the `intervention` limiting the command now (none when obeyed as sent),
    how many times each intervention began, the robot's radius (m), and
    how far its position estimate may be from the truth (m; its layer
    keeps its distances from a disc of radius + position_error; 0 from a
    robot that does not report it)."""

    state: str
    arena: int
    intervention: str
    counts: Dict[str, int]
    radius: float
    position_error: float = 0.0


@dataclass
class Waypoint:
    """A mission point (m) and an optional arrival time, seconds after the
    mission starts."""

    x: float
    y: float
    z: float = 0.0
    time: Optional[float] = None


@dataclass
class MissionAck:
    """A robot's answer to a mission."""

    id: int
    accepted: bool
    reason: str


@dataclass
class Channel:
    """A live channel as the router sees it."""

    name: str
    publisher: str
    rate_hz: float
    robots: List[str]
    idle_ms: int


@dataclass
class Notice:
    """A notice for humans and logs."""

    level: Level
    code: int
    text: str


@dataclass
class Time:
    """The router's answer to a time request."""

    nonce: int
    station_us: int


@dataclass
class Header:
    """An envelope's fields other than its body and tag."""

    seq: int
    stamp_us: int
    sender: str
    destination: str
    channel: str


@dataclass
class Message:
    """One decoded message. ``body`` is a dataclass above for the kinds this
    package interprets (telemetry, mission acks, channels, notices, time),
    otherwise the raw list of body fields."""

    kind: int
    header: Header
    body: Any
    auth: Optional[bytes] = field(default=None, repr=False)


# -------------------------------------------------------------- encoding


def _check_name(value: str, what: str) -> str:
    if len(value.encode("utf-8")) > MAX_NAME_LEN or any(
        c.isspace() or ord(c) < 0x20 or ord(c) == 0x7F for c in value
    ):
        raise ProtocolError(f"{what} {value!r}: at most 64 bytes, no spaces")
    return value


def envelope(
    kind: int,
    body: List[Any],
    *,
    seq: int,
    stamp_us: int,
    sender: str,
    destination: str = "",
    channel: str = "",
) -> List[Any]:
    """The nine-element envelope array (``auth`` nil) for ``body``."""
    return [
        VERSION,
        int(kind),
        seq & 0xFFFFFFFF,
        int(stamp_us),
        _check_name(sender, "sender"),
        _check_name(destination, "destination"),
        _check_name(channel, "channel"),
        body,
        None,
    ]


def encode(message: List[Any]) -> bytes:
    """MessagePack bytes of an envelope array, as mech-proto writes them
    (floats as float64, integers in their smallest form)."""
    data = msgpack.packb(message, use_bin_type=True, use_single_float=False)
    if len(data) > MAX_MESSAGE_LEN:
        raise ProtocolError(f"message of {len(data)} bytes, at most {MAX_MESSAGE_LEN}")
    return data


def command_body(command: Command) -> List[Any]:
    """The Command body: ``[command kind, payload]``."""
    kind, payload = command
    return [int(kind), payload]


def mission_body(
    mission_id: int,
    waypoints: Sequence[Waypoint],
    looped: bool = False,
    arrival_radius: float = 0.1,
    start_index: int = 0,
) -> List[Any]:
    """The Mission body (kind 7)."""
    if _real(arrival_radius, "arrival radius") <= 0.0:
        raise ProtocolError("arrival radius must be positive")
    if not 0 <= start_index <= len(waypoints):
        raise ProtocolError("start index is past the waypoints")
    points = [
        [
            _real(w.x, "waypoint x"),
            _real(w.y, "waypoint y"),
            _real(w.z, "waypoint z"),
            None if w.time is None else _arrival(w.time),
        ]
        for w in waypoints
    ]
    return [mission_id & 0xFFFFFFFF, points, bool(looped), float(arrival_radius), start_index]


# -------------------------------------------------------------- decoding


def _f(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ProtocolError(f"expected a number, got {v!r}")
    return float(v)


def _telemetry(b: List[Any]) -> Telemetry:
    if len(b) not in (11, 12, 13, 14):
        raise ProtocolError("telemetry has 11 to 14 fields")
    pose = Pose(*(_f(v) for v in b[0]))
    vel = Velocity(*(_f(v) for v in b[1]))
    mission = None if b[10] is None else MissionProgress(*b[10])
    return Telemetry(
        pose=pose,
        velocity=vel,
        mode=ControlMode(b[2]),
        channel=str(b[3]),
        offboard=b[4] == 1,
        failsafe=FailsafeState(b[5]),
        health=Health(b[6]),
        battery=None if b[7] is None else _f(b[7]),
        position_quality=_f(b[8]),
        actuators=[_f(v) for v in b[9]],
        mission=mission,
        stale=int(b[11]) if len(b) > 11 else 0,
        measured=len(b) > 12 and b[12] == 1,
        safety=_safety(b[13]) if len(b) > 13 and b[13] is not None else None,
    )


def _safety(b: Any) -> SafetyReport:
    # Fields are added at the end (position_error after radius): a report
    # has at least the first five, and what follows the known ones is
    # left for a newer client.
    if not isinstance(b, list) or len(b) < 5 or not isinstance(b[3], list) or len(b[3]) != 6:
        raise ProtocolError("a safety report has at least 5 fields, its counts 6")
    state, arena, intervention, counts, radius = b[:5]
    position_error = b[5] if len(b) > 5 else 0.0
    if not (isinstance(state, int) and 0 <= state < len(SAFETY_STATES)):
        raise ProtocolError(f"unknown safety state {state!r}")
    if not (isinstance(intervention, int) and 0 <= intervention < len(INTERVENTIONS)):
        raise ProtocolError(f"unknown intervention {intervention!r}")
    if not all(isinstance(c, int) and not isinstance(c, bool) for c in counts + [arena]):
        raise ProtocolError("a safety report's arena and counts are integers")
    return SafetyReport(
        state=SAFETY_STATES[state],
        arena=arena,
        intervention=INTERVENTIONS[intervention],
        counts=dict(zip(INTERVENTIONS[1:], counts)),
        radius=_f(radius),
        position_error=_f(position_error),
    )


def _body(kind: int, b: List[Any]) -> Any:
    if kind == Kind.TELEMETRY:
        return _telemetry(b)
    if kind == Kind.MISSION_ACK:
        return MissionAck(int(b[0]), bool(b[1]), str(b[2]))
    if kind == Kind.CHANNELS:
        return [Channel(str(c[0]), str(c[1]), _f(c[2]), list(c[3]), int(c[4])) for c in b[0]]
    if kind == Kind.NOTICE:
        return Notice(Level(b[0]), int(b[1]), str(b[2]))
    if kind == Kind.TIME:
        return Time(int(b[0]), int(b[1]))
    return b


def decode(data: bytes) -> Message:
    """Decodes one message. Raises :class:`ProtocolError` for anything that
    is not a well-formed version-1 message."""
    if not data:
        raise ProtocolError("empty message")
    if len(data) > MAX_MESSAGE_LEN:
        raise ProtocolError("oversized message")
    try:
        m = msgpack.unpackb(data, raw=False, strict_map_key=False)
    except Exception as e:  # msgpack raises several types for bad input
        raise ProtocolError(f"malformed: {e}") from e
    if not isinstance(m, list) or len(m) != 9:
        raise ProtocolError("malformed: not a nine-element array")
    if m[0] != VERSION:
        raise ProtocolError(f"unsupported version {m[0]!r}")
    kind, seq, stamp, sender, dest, channel, body, auth = m[1:]
    if not isinstance(kind, int) or not isinstance(body, list):
        raise ProtocolError("malformed: kind or body")
    if not all(isinstance(s, str) for s in (sender, dest, channel)):
        raise ProtocolError("malformed: names")
    if auth is not None and not isinstance(auth, bytes):
        raise ProtocolError("malformed: auth")
    try:
        decoded = _body(kind, body)
    except (IndexError, TypeError, ValueError) as e:
        raise ProtocolError(f"malformed body of kind {kind}: {e}") from e
    return Message(kind, Header(seq, stamp, sender, dest, channel), decoded, auth)

