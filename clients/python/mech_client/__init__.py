"""mech_client: talk to a MECH ground station's router from Python.

Publish commands on a channel, subscribe to telemetry, discover channels,
send waypoint missions, sign with a key from ``mech-gcs keygen``, and take
the station's time when the local clock may be off::

    from mech_client import Client

    with Client("ext_python") as mech:          # the demo: 127.0.0.1:7400
        mech.subscribe()
        mech.wait_telemetry("robot_1")
        while True:
            mech.poll(0.05)                         # 20 Hz
            pose = mech.fresh_telemetry("robot_1").pose   # StaleTelemetry if old
            mech.twist("robot_1", "ext/python", vx=0.2, wz=0.3)

The wire format is docs/protocol.md; ``mech_client.protocol`` encodes it
byte for byte as the reference implementation does.
"""

from .client import STALE_AFTER, Client, MechError, RouterUnreachable, StaleTelemetry, parse_address
from .protocol import (
    AutopilotAction,
    Channel,
    CommandKind,
    ControlMode,
    FailsafeState,
    Health,
    Kind,
    Message,
    MissionAck,
    Notice,
    Pose,
    ProtocolError,
    Telemetry,
    Velocity,
    Waypoint,
    actuators,
    steering_throttle,
    stop,
    twist,
    velocity_heading,
)
from .signing import Key, KeyFileError, parse_key, read_key

__all__ = [
    "AutopilotAction",
    "Channel",
    "Client",
    "CommandKind",
    "ControlMode",
    "FailsafeState",
    "Health",
    "Key",
    "KeyFileError",
    "Kind",
    "MechError",
    "Message",
    "MissionAck",
    "Notice",
    "Pose",
    "ProtocolError",
    "RouterUnreachable",
    "STALE_AFTER",
    "StaleTelemetry",
    "Telemetry",
    "Velocity",
    "Waypoint",
    "actuators",
    "parse_address",
    "parse_key",
    "read_key",
    "steering_throttle",
    "stop",
    "twist",
    "velocity_heading",
]

__version__ = "0.1.0"
