"""A fake PX4 autopilot for the MAVLink tests, written with pymavlink.

It speaks MAVLink 2 to the agent over UDP (udpout to the agent's udpin
port), as PX4 SITL's offboard link does, and flies a point vehicle:

- sends HEARTBEAT (PX4, quadrotor; armed flag and custom mode as they are)
  at 1 Hz, LOCAL_POSITION_NED and ATTITUDE at 20 Hz, SYS_STATUS (87 %)
  at 1 Hz;
- starts at 1 m north, 2 m east, 3 m up (z = -3), facing east (yaw pi/2);
- obeys COMMAND_LONG ARM_DISARM and DO_SET_MODE, answering COMMAND_ACK;
- while armed in OFFBOARD, integrates the last velocity setpoint
  (SET_POSITION_TARGET_LOCAL_NED) and yaw rate; otherwise holds still.

Prints one JSON line per event to stdout: every HEARTBEAT, setpoint and
command received (with the wall-clock time), and the vehicle's state once a
second. Runs for SECONDS.

    python3 fake_autopilot.py AGENT_PORT SECONDS
"""

import json
import math
import os
import sys
import time

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

PX4_OFFBOARD = 6 << 16
PX4_POSCTL = 3 << 16


def main() -> int:
    port, seconds = int(sys.argv[1]), float(sys.argv[2])
    link = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=1, source_component=1, dialect="common"
    )
    mav = link.mav
    mav.WIRE_PROTOCOL_VERSION = "2.0"
    m = mavutil.mavlink
    north, east, down, yaw = 1.0, 2.0, -3.0, math.pi / 2
    vel = (0.0, 0.0, 0.0)
    yaw_rate = 0.0
    armed, custom_mode = False, PX4_POSCTL
    start = time.time()
    last_setpoint = 0.0
    next_fast = next_slow = start

    def emit(event, **fields):
        fields.update(event=event, t=time.time())
        print(json.dumps(fields), flush=True)

    while time.time() - start < seconds:
        now = time.time()
        if now >= next_slow:
            next_slow += 1.0
            base = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (m.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
            mav.heartbeat_send(m.MAV_TYPE_QUADROTOR, m.MAV_AUTOPILOT_PX4, base, custom_mode, m.MAV_STATE_ACTIVE)
            mav.sys_status_send(0, 0, 0, 500, 12_600, -1, 87, 0, 0, 0, 0, 0, 0)
            emit("state", north=north, east=east, down=down, yaw=yaw, armed=armed, mode=custom_mode >> 16)
        if now >= next_fast:
            dt = 0.05
            next_fast += dt
            flying = armed and custom_mode == PX4_OFFBOARD and now - last_setpoint < 0.5
            v, r = (vel, yaw_rate) if flying else ((0.0, 0.0, 0.0), 0.0)
            north, east, down = north + v[0] * dt, east + v[1] * dt, down + v[2] * dt
            yaw = math.atan2(math.sin(yaw + r * dt), math.cos(yaw + r * dt))
            boot_ms = int((now - start) * 1000)
            mav.local_position_ned_send(boot_ms, north, east, down, v[0], v[1], v[2])
            mav.attitude_send(boot_ms, 0.0, 0.0, yaw, 0.0, 0.0, r)
        msg = link.recv_match(blocking=True, timeout=0.01)
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            emit("heartbeat", type=msg.type, autopilot=msg.autopilot, system=msg.get_srcSystem(),
                 component=msg.get_srcComponent(), mavlink2=msg.get_msgbuf()[0] == 0xFD)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            last_setpoint = time.time()
            vel, yaw_rate = (msg.vx, msg.vy, msg.vz), msg.yaw_rate
            emit("setpoint", frame=msg.coordinate_frame, type_mask=msg.type_mask, vx=msg.vx, vy=msg.vy,
                 vz=msg.vz, yaw_rate=msg.yaw_rate, target=[msg.target_system, msg.target_component],
                 mavlink2=msg.get_msgbuf()[0] == 0xFD)
        elif kind == "COMMAND_LONG":
            emit("command", command=msg.command, params=[msg.param1, msg.param2, msg.param3])
            result = m.MAV_RESULT_ACCEPTED
            if msg.command == m.MAV_CMD_COMPONENT_ARM_DISARM:
                armed = msg.param1 == 1.0
            elif msg.command == m.MAV_CMD_DO_SET_MODE:
                custom_mode = (int(msg.param2) << 16) | (int(msg.param3) << 24)
            else:
                result = m.MAV_RESULT_UNSUPPORTED
            mav.command_ack_send(msg.command, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
