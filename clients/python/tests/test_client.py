"""The client against a stand-in router on loopback: ``poll(period)``
returns when its period is over however much arrives, a router that is not
there raises :class:`RouterUnreachable` instead of being ignored, and
telemetry too old to steer by raises :class:`StaleTelemetry` (time is the
client module's ``time.monotonic``, patched: no sleeps decide a test).
"""

from __future__ import annotations

import os
import socket
import sys
import threading
import time
import unittest
from unittest import mock

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from mech_client import Client, RouterUnreachable, StaleTelemetry  # noqa: E402
from mech_client import protocol as p  # noqa: E402


def telemetry(robot: str, x: float, seq: int) -> bytes:
    """A Telemetry message from ``robot`` as the router forwards it."""
    body = [
        [x, 0.0, 0.0, 0.0],  # pose
        [0.0, 0.0, 0.0, 0.0],  # velocity
        0,  # mode
        "ext/python",
        0,  # computation
        0,  # failsafe
        0,  # health
        None,  # battery
        1.0,  # position quality
        [],  # actuators
        None,  # mission
        0,  # stale
        0,  # velocity source
    ]
    message = p.envelope(
        p.Kind.TELEMETRY, body, seq=seq, stamp_us=1, sender=robot, destination="py", channel=""
    )
    return p.encode(message)


class StandIn:
    """A UDP socket where the router would be, sending telemetry to the
    client every ``every`` seconds once it has heard from it."""

    def __init__(self, every: float) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.address = "127.0.0.1:%d" % self.sock.getsockname()[1]
        self.every = every
        self.stop = threading.Event()
        self.sent = 0
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        self.sock.settimeout(5.0)
        try:
            _, client = self.sock.recvfrom(2048)
        except OSError:
            return
        while not self.stop.is_set():
            self.sent += 1
            self.sock.sendto(telemetry("robot_1", 0.01 * self.sent, self.sent), client)
            self.stop.wait(self.every)

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        self.sock.close()


class FakeTime:
    """The ``time`` module as the client sees it, with a monotonic clock
    the test moves."""

    def __init__(self) -> None:
        self.now = 1000.0

    def monotonic(self) -> float:
        return self.now

    def __getattr__(self, name: str):
        return getattr(time, name)


class PollTests(unittest.TestCase):
    def test_poll_returns_when_its_period_is_over_not_at_the_first_message(self) -> None:
        router = StandIn(every=0.005)
        try:
            with Client("py", router.address) as mech:
                mech.subscribe()
                mech.wait_telemetry("robot_1", timeout=5.0)
                start = time.monotonic()
                got = []
                for _ in range(4):
                    got.extend(mech.poll(0.05))
                took = time.monotonic() - start
                # Four periods of 50 ms, messages arriving every 5 ms all
                # along: the loop ran at 20 Hz, not as fast as messages came.
                self.assertGreaterEqual(took, 0.2)
                self.assertLess(took, 0.5)
                self.assertGreater(len(got), 8, "what arrived was taken in")
                self.assertEqual(mech.poll(0.0).__class__, list)
        finally:
            router.close()


class BlindTests(unittest.TestCase):
    def test_a_router_that_is_not_there_raises_instead_of_being_ignored(self) -> None:
        gone = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        gone.bind(("127.0.0.1", 0))
        address = "127.0.0.1:%d" % gone.getsockname()[1]
        gone.close()
        with Client("py", address) as mech:
            with self.assertRaises(RouterUnreachable) as raised:
                # The first send goes out; the kernel's port unreachable
                # comes back and is reported by the next call.
                for _ in range(10):
                    mech.twist("robot_1", "ext/python", vx=0.1)
                    mech.poll(0.02)
            self.assertIn("is the station running?", str(raised.exception))
            self.assertGreaterEqual(mech.unreachable, 1)

    def test_telemetry_older_than_a_controller_steers_by_raises(self) -> None:
        router = StandIn(every=0.01)
        clock = FakeTime()
        try:
            with Client("py", router.address) as mech:
                with mock.patch("mech_client.client.time", clock):
                    with self.assertRaises(StaleTelemetry) as none_yet:
                        mech.fresh_telemetry("robot_1")
                    self.assertIn("no telemetry yet", str(none_yet.exception))
                    mech.subscribe()
                    # Take in messages until the first telemetry arrives
                    # (the stand-in starts once it heard the subscription).
                    for _ in range(100000):
                        if "robot_1" in mech.telemetry:
                            break
                        mech.poll(0.0)
                    self.assertEqual(mech.fresh_telemetry("robot_1").pose.y, 0.0)
                    clock.now += 0.6
                    with self.assertRaises(StaleTelemetry) as stale:
                        mech.fresh_telemetry("robot_1")
                    self.assertAlmostEqual(stale.exception.age, 0.6, places=6)
                    self.assertIn("0.60 s old", str(stale.exception))
                    self.assertEqual(mech.fresh_telemetry("robot_1", max_age=1.0).pose.z, 0.0)
        finally:
            router.close()


if __name__ == "__main__":
    unittest.main()
