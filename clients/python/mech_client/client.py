"""A MECH controller's connection to the router over UDP: publish commands,
subscribe to telemetry, discover channels, send missions, sign with a key,
and take the station's time.

The client is synchronous and single-threaded: call :meth:`Client.poll`
(or any method that waits) often enough to take in telemetry and renew the
subscription. A control loop at 10-50 Hz that calls ``poll(period)`` once
per iteration (it returns when the period is over) is the intended use.

It never drives blind in silence: a router that is not there (ICMP port
unreachable) raises :class:`RouterUnreachable` from the next call, and
:meth:`Client.fresh_telemetry` raises :class:`StaleTelemetry` when a
robot's latest telemetry is older than a controller should steer by.
"""

from __future__ import annotations

import math
import random
import socket
import time
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple, TypeVar

from . import protocol as p
from .signing import ROUTER_BIT, Freshness, Key, read_key

T = TypeVar("T")

RENEW_EVERY = 2.0
"""Seconds between subscription renewals (the router drops a subscriber
it has not heard from for 5 s)."""


STALE_AFTER = 0.5
"""Seconds after which :meth:`Client.fresh_telemetry` calls a robot's
telemetry stale: the agents' failsafe timeout, and the router's (robots
send at 20 Hz)."""


class MechError(RuntimeError):
    """A request the router or a robot did not answer in time, or a link a
    controller cannot steer over."""


class RouterUnreachable(MechError):
    """Nothing listens at the router's address: the station is down (the
    kernel's ICMP port unreachable). Commands sent now reach no robot."""


class StaleTelemetry(MechError):
    """A robot's latest telemetry is too old to steer by (the robot, its
    link or the station went quiet, or the subscription lapsed)."""

    def __init__(self, robot: str, age: float) -> None:
        what = "no telemetry yet" if math.isinf(age) else f"telemetry {age:.2f} s old"
        super().__init__(f"{robot}: {what}; not steering on it")
        self.robot = robot
        self.age = age


def parse_address(address: str) -> Tuple[str, int]:
    """``"host:port"`` as a socket address."""
    host, sep, port = address.rpartition(":")
    if not sep or not host:
        raise ValueError(f"expected HOST:PORT, got {address!r}")
    return host.strip("[]"), int(port)


class Client:
    """One controller (or tool) talking to one router.

    :param name: the sender name; with a key, the name the key was made for.
    :param router: the router's UDP address, ``HOST:PORT``.
    :param key: sign every message with it, and accept only what the router
        signed for us (required by a station with keys).
    :param sync_clock: ask the router for its time first (``TimeRequest``),
        for a machine whose clock may be off: a signed message's stamp must
        be within 10 s of the station's clock.
    """

    def __init__(
        self,
        name: Optional[str] = None,
        router: str = "127.0.0.1:7400",
        key: Optional[Key] = None,
        sync_clock: bool = False,
    ) -> None:
        if key is not None:
            if name is not None and name != key.name:
                raise ValueError(f"the key is {key.name!r}'s, not {name!r}'s")
            name = key.name
        if name is None:
            raise ValueError("a client needs a name (or a key)")
        p._check_name(name, "name")
        self.name = name
        self.key = key
        host, port = parse_address(router)
        self.router = (socket.gethostbyname(host), port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1" if self.router[0].startswith("127.") else "", 0))
        # Connected: the kernel then reports the router's ICMP errors (port
        # unreachable: the station is down) on this socket's next call.
        self.sock.connect(self.router)
        self._seq = 0
        self._offset_us = 0
        self._last_stamp = 0
        self._freshness = Freshness()
        self._subscribed_at: Optional[float] = None
        self._next_mission_id = (int(time.time()) * 16 + random.randrange(16)) & 0xFFFFFFFF
        self.telemetry: Dict[str, p.Telemetry] = {}
        """The latest telemetry of each robot, by name (needs :meth:`subscribe`)."""
        self.telemetry_at: Dict[str, float] = {}
        """When (``time.monotonic()``) each robot's latest telemetry arrived."""
        self.notices: List[Tuple[str, p.Notice]] = []
        """Notices sent to us (sender, notice), oldest first, at most 100."""
        self.refused = 0
        """Messages dropped as undecodable, unsigned, forged or replayed."""
        self.unreachable = 0
        """Times the router's address answered "port unreachable"."""
        self._replies: List[p.Message] = []
        if sync_clock:
            self.sync_time()

    @classmethod
    def from_key_file(cls, path: str, router: str = "127.0.0.1:7400", sync_clock: bool = True) -> "Client":
        """A signing client with the key file ``mech-gcs keygen NAME`` wrote."""
        return cls(key=read_key(path), router=router, sync_clock=sync_clock)

    def close(self) -> None:
        """Unsubscribes (if subscribed) and closes the socket."""
        if self._subscribed_at is not None:
            try:
                self._send(p.Kind.SUBSCRIBE, [False], p.ROUTER)
            except (OSError, RouterUnreachable):
                pass
        self.sock.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ clock

    def now_us(self) -> int:
        """Station time in µs since the Unix epoch: the local clock plus the
        offset :meth:`sync_time` measured (zero until then)."""
        return time.time_ns() // 1000 + self._offset_us

    def sync_time(self, timeout: float = 2.0) -> int:
        """Asks the router for its clock and adopts it; returns the offset
        (station minus local, µs). The router answers a key at most ten times
        a second, so a lost answer is retried after 0.2 s."""
        nonce = random.getrandbits(64)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            sent = time.time_ns() // 1000
            self._send(p.Kind.TIME_REQUEST, [nonce], p.ROUTER)
            answer = self._await(
                lambda m: m.body if m.kind == p.Kind.TIME and m.body.nonce == nonce else None,
                min(0.2, max(0.0, deadline - time.monotonic())),
            )
            if answer is not None:
                received = time.time_ns() // 1000
                self._offset_us = answer.station_us - (sent + received) // 2
                return self._offset_us
        raise MechError("the router did not answer the time request")

    # ---------------------------------------------------------- commands

    def publish(self, robot: str, channel: str, command: p.Command) -> None:
        """Sends ``command`` for ``robot`` on ``channel``. The router passes it
        on only while the robot is routed to the channel."""
        self._send(p.Kind.COMMAND, p.command_body(command), robot, channel)
        self._renew()

    def twist(self, robot: str, channel: str, vx: float = 0.0, vy: float = 0.0, vz: float = 0.0, wz: float = 0.0) -> None:
        """Publishes a body-frame twist (m/s, rad/s)."""
        self.publish(robot, channel, p.twist(vx, vy, vz, wz))

    def velocity_heading(self, robot: str, channel: str, speed: float, heading: float) -> None:
        """Publishes a velocity-heading command (m/s, world heading rad)."""
        self.publish(robot, channel, p.velocity_heading(speed, heading))

    def stop(self, robot: str, channel: str) -> None:
        """Publishes a (not latched) stop."""
        self.publish(robot, channel, p.stop())

    def publish_fleet(self, channel: str, parts: Mapping[str, p.Command]) -> None:
        """One message with a command per robot (a FleetCommand); each robot
        routed to ``channel`` receives its own part."""
        body = [[[robot, p.command_body(cmd)] for robot, cmd in parts.items()]]
        self._send(p.Kind.FLEET_COMMAND, body, p.ROUTER, channel)
        self._renew()

    # --------------------------------------------------------- telemetry

    def subscribe(self) -> None:
        """Asks the router for every robot's telemetry; renewed by
        :meth:`poll` and :meth:`publish` every 2 s."""
        self._subscribed_at = time.monotonic()
        self._send(p.Kind.SUBSCRIBE, [True], p.ROUTER)

    def unsubscribe(self) -> None:
        """Stops the telemetry fan-out to this client."""
        self._subscribed_at = None
        self._send(p.Kind.SUBSCRIBE, [False], p.ROUTER)

    def poll(self, period: float = 0.0) -> List[p.Message]:
        """Takes in what arrives for ``period`` seconds and returns then
        (``poll(0)``: what is waiting now), so a loop that calls it once per
        iteration runs at ``1 / period`` at most. Updates :attr:`telemetry`,
        renews the subscription when due, and returns the messages. Raises
        :class:`RouterUnreachable` when the station is not there."""
        return self._take(period, first=False)

    def _take(self, timeout: float, first: bool) -> List[p.Message]:
        """Takes in messages until ``timeout`` has passed (``first``: until
        the first one too, whichever comes first), then what is waiting."""
        self._renew()
        got: List[p.Message] = []
        deadline = time.monotonic() + timeout
        while True:
            left = max(deadline - time.monotonic(), 0.0)
            self.sock.settimeout(0.0 if (first and got) else left)
            try:
                data, source = self.sock.recvfrom(p.MAX_MESSAGE_LEN + 1)
            except (BlockingIOError, socket.timeout):
                if left <= 0.0 or (first and got):
                    break
                continue
            except ConnectionRefusedError:
                self._unreachable()
            if not self._from_router(source):
                continue
            message = self._accept(data)
            if message is not None:
                got.append(message)
        return got

    def _unreachable(self) -> None:
        self.unreachable += 1
        raise RouterUnreachable(
            f"nothing listens at the router {self.router[0]}:{self.router[1]} "
            "(port unreachable): is the station running?"
        )

    def telemetry_age(self, robot: str) -> float:
        """Seconds since the robot's latest telemetry arrived (infinite
        before the first)."""
        at = self.telemetry_at.get(robot)
        return math.inf if at is None else time.monotonic() - at

    def fresh_telemetry(self, robot: str, max_age: float = STALE_AFTER) -> p.Telemetry:
        """The robot's latest telemetry, if it arrived within ``max_age``
        seconds; else raises :class:`StaleTelemetry` (a controller that
        steers on it would drive blind). Subscribes if not yet subscribed."""
        if self._subscribed_at is None:
            self.subscribe()
        age = self.telemetry_age(robot)
        if age > max_age:
            raise StaleTelemetry(robot, age)
        return self.telemetry[robot]

    def wait_telemetry(self, robot: str, timeout: float = 5.0, newer_than: Optional[float] = None) -> p.Telemetry:
        """The robot's telemetry, waiting up to ``timeout`` s for it (for one
        received after ``newer_than``, a ``time.monotonic()`` reading, when
        given). Subscribes if not yet subscribed."""
        if self._subscribed_at is None:
            self.subscribe()
        deadline = time.monotonic() + timeout
        while True:
            at = self.telemetry_at.get(robot)
            if at is not None and (newer_than is None or at > newer_than):
                return self.telemetry[robot]
            left = deadline - time.monotonic()
            if left <= 0:
                raise StaleTelemetry(robot, self.telemetry_age(robot))
            self._take(min(left, 0.1), first=True)

    # --------------------------------------------------------- discovery

    def channels(self, timeout: float = 2.0) -> List[p.Channel]:
        """The live channels: name, last publisher, rate and routed robots."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self._send(p.Kind.CHANNELS_REQUEST, [], p.ROUTER)
            answer = self._await(
                lambda m: m.body if m.kind == p.Kind.CHANNELS else None,
                min(0.5, max(0.0, deadline - time.monotonic())),
            )
            if answer is not None:
                return answer
        raise MechError("the router did not answer the channels request")

    # ---------------------------------------------------------- missions

    def send_mission(
        self,
        robot: str,
        channel: str,
        waypoints: Sequence[p.Waypoint],
        looped: bool = False,
        arrival_radius: float = 0.1,
        start_index: int = 0,
        timeout: float = 5.0,
    ) -> p.MissionAck:
        """Sends a waypoint mission to ``robot`` on ``channel`` and waits for
        its acknowledgement (the router repeats it to the robot; this client
        repeats it to the router every second). The robot runs it while
        routed to ``channel``. Raises :class:`MechError` without an answer."""
        mission_id = self._next_mission_id
        self._next_mission_id = (mission_id + 1) & 0xFFFFFFFF
        body = p.mission_body(mission_id, waypoints, looped, arrival_radius, start_index)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self._send(p.Kind.MISSION, body, robot, channel)
            ack = self._await(
                lambda m: m.body
                if m.kind == p.Kind.MISSION_ACK and m.header.sender == robot and m.body.id == mission_id
                else None,
                min(1.0, max(0.0, deadline - time.monotonic())),
            )
            if ack is not None:
                return ack
        raise MechError(f"{robot} did not acknowledge mission {mission_id}")

    # --------------------------------------------------------- operators

    def autopilot(self, robot: str, action: p.AutopilotAction, altitude: float = 0.0) -> None:
        """Asks a robot's autopilot to arm, disarm, change mode, land or take
        off (``altitude`` m). Only an operator key may send this; the robot
        reports the outcome as a notice in the station's event log."""
        body = [robot, int(action), p._real(altitude, "altitude")]
        self._send(p.Kind.AUTOPILOT, body, p.ROUTER)

    # ---------------------------------------------------------- internals

    def _stamp(self) -> int:
        stamp = max(self.now_us(), self._last_stamp + 1)
        self._last_stamp = stamp
        return stamp

    def _send(self, kind: int, body: list, destination: str, channel: str = "") -> None:
        self._seq = (self._seq + 1) & 0xFFFFFFFF
        stamp = self._stamp()
        message = p.envelope(
            kind,
            body,
            seq=self._seq,
            stamp_us=stamp,
            sender=self.name,
            destination=destination,
            channel=channel,
        )
        data = p.encode(message)
        if self.key is not None:
            data = self.key.seal(data[:-1], stamp)
        try:
            self.sock.send(data)
        except ConnectionRefusedError:
            self._unreachable()

    def _renew(self) -> None:
        at = self._subscribed_at
        if at is not None and time.monotonic() - at >= RENEW_EVERY:
            self.subscribe()

    def _from_router(self, source: Tuple[str, int]) -> bool:
        return (source[0], source[1]) == self.router

    def _accept(self, data: bytes) -> Optional[p.Message]:
        try:
            message = p.decode(data)
        except p.ProtocolError:
            self.refused += 1
            return None
        if self.key is not None:
            opened = self.key.open(data)
            if opened is None or not opened[0] & ROUTER_BIT or not self._freshness.accept(opened[1]):
                self.refused += 1
                return None
        if message.kind == p.Kind.TELEMETRY:
            self.telemetry[message.header.sender] = message.body
            self.telemetry_at[message.header.sender] = time.monotonic()
        elif message.kind == p.Kind.NOTICE:
            self.notices.append((message.header.sender, message.body))
            del self.notices[:-100]
        else:
            self._replies.append(message)
            del self._replies[:-100]
        return message

    def _await(self, pick: Callable[[p.Message], Optional[T]], timeout: float) -> Optional[T]:
        """Polls until ``pick`` returns something for a reply, or ``timeout``."""
        deadline = time.monotonic() + timeout
        while True:
            for i, m in enumerate(self._replies):
                try:
                    found = pick(m)
                except AttributeError:
                    found = None
                if found is not None:
                    del self._replies[i]
                    return found
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._take(min(left, 0.05), first=True)
