"""The Python encoder against the golden bytes of docs/protocol.md and
proto/tests/golden.rs, the signing rules, and the decoder's refusals.

Run with ``python3 -m unittest discover clients/python/tests`` (or pytest).
"""

from __future__ import annotations

import os
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from mech_client import protocol as p  # noqa: E402
from mech_client.signing import Freshness, Key, KeyFileError, parse_key, read_key  # noqa: E402

# proto/tests/golden.rs HEARTBEAT: robot_1 -> router, seq 7, t = 1 s, uptime 1500 ms.
HEARTBEAT = bytes.fromhex(
    "99 01 03 07 ce 00 0f 42 40"
    " a7 726f626f745f31 a6 726f75746572 a0"
    " 91 cd 05 dc c0"
)

# docs/protocol.md "Example: a Twist command" (and golden.rs TWIST).
TWIST = bytes.fromhex(
    "99 01 05 07 ce 00 0f 42 40"
    " a3 676373 a7 726f626f745f31 a5 6a6f792f30"
    " 92 04 94"
    " cb 3fe0000000000000 cb 0000000000000000 cb 0000000000000000 cb bfd0000000000000"
    " c0"
)

# golden.rs ROUTE: gcs -> robot_1, Route robot_1 to joy/0, epoch 3.
ROUTE = bytes.fromhex(
    "99 01 09 07 ce 00 0f 42 40"
    " a3 676373 a7 726f626f745f31 a0"
    " 93 a7 726f626f745f31 a5 6a6f792f30 03 c0"
)

# docs/protocol.md *Signing*: the tag replacing TWIST's final nil when gcs
# signs it with the published test key on link 0 at 1_700_000_000_000_000 µs.
TWIST_TAG = bytes.fromhex(
    "c4 1d 63 0d cd 29 00 00 06 0a 24 18 1e 40 00"
    " 6b 31 24 bf af 0d 4c 91 43 2e 88 ac b7 e5 43 86"
)

TEST_KEY = Key("gcs", bytes(range(32)))


def header(kind: int, body: list, sender: str, destination: str, channel: str) -> list:
    return p.envelope(kind, body, seq=7, stamp_us=1_000_000, sender=sender, destination=destination, channel=channel)


class GoldenBytes(unittest.TestCase):
    def test_twist_command_encodes_to_the_documented_bytes(self) -> None:
        msg = header(p.Kind.COMMAND, p.command_body(p.twist(0.5, 0.0, 0.0, -0.25)), "gcs", "robot_1", "joy/0")
        self.assertEqual(p.encode(msg).hex(), TWIST.hex())

    def test_integers_given_for_reals_still_travel_as_float64(self) -> None:
        msg = header(p.Kind.COMMAND, p.command_body(p.twist(0.5, 0, 0, -0.25)), "gcs", "robot_1", "joy/0")
        self.assertEqual(p.encode(msg), TWIST)

    def test_heartbeat_and_route_encode_to_the_golden_bytes(self) -> None:
        self.assertEqual(p.encode(header(p.Kind.HEARTBEAT, [1500], "robot_1", "router", "")), HEARTBEAT)
        self.assertEqual(p.encode(header(p.Kind.ROUTE, ["robot_1", "joy/0", 3], "gcs", "robot_1", "")), ROUTE)

    def test_golden_messages_decode(self) -> None:
        m = p.decode(TWIST)
        self.assertEqual((m.kind, m.header.sender, m.header.destination, m.header.channel), (5, "gcs", "robot_1", "joy/0"))
        self.assertEqual((m.header.seq, m.header.stamp_us), (7, 1_000_000))
        self.assertEqual(m.body, [4, [0.5, 0.0, 0.0, -0.25]])
        self.assertIsNone(m.auth)
        self.assertEqual(p.decode(HEARTBEAT).body, [1500])


class Signing(unittest.TestCase):
    def test_the_signed_twist_matches_the_documented_tag(self) -> None:
        self.assertEqual(TEST_KEY.key_id.hex(), "630dcd29")
        signed = TEST_KEY.seal(TWIST[:-1], 1_700_000_000_000_000)
        self.assertEqual(signed.hex(), (TWIST[:-1] + TWIST_TAG).hex())

    def test_a_signed_message_opens_and_a_changed_byte_does_not(self) -> None:
        signed = TEST_KEY.seal(TWIST[:-1], 1_700_000_000_000_000, link=0x80)
        self.assertEqual(TEST_KEY.open(signed), (0x80, 1_700_000_000_000_000))
        self.assertEqual(p.decode(signed).auth[:5], bytes.fromhex("630dcd29 80"))
        for i in (0, 20, len(signed) - 1):
            forged = bytearray(signed)
            forged[i] ^= 1
            self.assertIsNone(TEST_KEY.open(bytes(forged)), f"byte {i}")
        self.assertIsNone(Key("gcs", bytes(32)).open(signed))
        self.assertIsNone(TEST_KEY.open(TWIST))

    def test_freshness_refuses_replays_and_stale_stamps(self) -> None:
        f = Freshness()
        self.assertTrue(f.accept(10_000_000))
        self.assertFalse(f.accept(10_000_000), "a repeat")
        self.assertTrue(f.accept(10_500_000))
        self.assertTrue(f.accept(10_200_000), "a little late is not lost")
        self.assertFalse(f.accept(9_000_000), "over 1 s behind")
        for i in range(64):
            self.assertTrue(f.accept(11_000_000 + i))
        self.assertFalse(f.accept(10_900_000), "64 newer messages already")

    def test_key_files(self) -> None:
        text = '# comment\nname = "python"\nsecret = "' + bytes(range(32)).hex() + '"\n'
        key = parse_key(text)
        self.assertEqual((key.name, key.secret), ("python", bytes(range(32))))
        with self.assertRaises(KeyFileError):
            parse_key('name = "x"\n')
        with self.assertRaises(KeyFileError):
            parse_key("name = x\nsecret = y\n")
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "k.key")
            with open(path, "w", encoding="utf-8") as f:
                f.write(text)
            os.chmod(path, 0o644)
            with self.assertRaises(KeyFileError):
                read_key(path)
            os.chmod(path, 0o600)
            self.assertEqual(read_key(path), key)


class Decoding(unittest.TestCase):
    def test_bad_input_is_a_protocol_error(self) -> None:
        for bad in (b"", b"\xc1", TWIST[:-3], b"\x99\x02" + TWIST[2:], b"\x93\x01\x02\x03", b"\xff" * 70_000):
            with self.assertRaises(p.ProtocolError, msg=bad[:8].hex()):
                p.decode(bad)

    def test_telemetry_with_and_without_the_stale_field(self) -> None:
        body = [[1.0, 2.0, 0.0, 0.5], [0.1, 0.0, 0.0, 0.0], 4, "ext/python", 0, 0, 0, 0.8, 1.0, [0.2, 0.2], [5, 1, 3]]
        for fields in (body, body + [2]):
            m = p.decode(p.encode(header(p.Kind.TELEMETRY, fields, "robot_1", "router", "")))
            t = m.body
            self.assertIsInstance(t, p.Telemetry)
            self.assertEqual((t.pose.x, t.pose.y, t.pose.heading), (1.0, 2.0, 0.5))
            self.assertEqual((t.mode, t.channel, t.battery), (p.ControlMode.TWIST, "ext/python", 0.8))
            self.assertEqual(t.mission, p.MissionProgress(5, 1, 3))
            self.assertEqual(t.stale, len(fields) - 11 and 2)

    def test_telemetry_with_a_safety_report(self) -> None:
        body = [[1.0, 2.0, 0.0, 0.5], [0.1, 0.0, 0.0, 0.0], 4, "ext/python", 0, 0, 0, 0.8, 1.0, [0.2, 0.2], None, 0, 1]
        report = [1, 7, 3, [0, 0, 2, 0, 0, 0], 0.15]
        t = p.decode(p.encode(header(p.Kind.TELEMETRY, body + [report], "robot_1", "router", ""))).body
        self.assertEqual(t.safety, p.SafetyReport("on", 7, "separation", {
            "fence": 0, "keep_out": 0, "separation": 2, "stale_neighbours": 0, "slow_zone": 0, "returning": 0}, 0.15))
        self.assertIsNone(p.decode(p.encode(header(p.Kind.TELEMETRY, body, "robot_1", "router", ""))).body.safety)
        # The position error a newer robot adds, and whatever an even newer
        # one adds after it.
        for extra in ([0.05], [0.05, "later"]):
            t = p.decode(p.encode(header(p.Kind.TELEMETRY, body + [report + extra], "robot_1", "router", ""))).body
            self.assertEqual((t.safety.radius, t.safety.position_error), (0.15, 0.05))
        self.assertEqual(p.decode(p.encode(header(p.Kind.TELEMETRY, body + [report], "robot_1", "router", ""))).body.safety.position_error, 0.0)
        for bad in ([9, 7, 3, [0] * 6, 0.15], [1, 7, 3, [0] * 6, 0.15, "far"], [1, 7, 3, [0] * 6], [1, 7, 3, [0] * 5, 0.15], [1, 7, 12, [0] * 6, 0.15], "on"):
            with self.assertRaises(p.ProtocolError):
                p.decode(p.encode(header(p.Kind.TELEMETRY, body + [bad], "robot_1", "router", "")))

    def test_values_that_cannot_be_sent_are_refused(self) -> None:
        with self.assertRaises(p.ProtocolError):
            p.twist(float("nan"))
        with self.assertRaises(p.ProtocolError):
            p.steering_throttle(1.5, 0)
        with self.assertRaises(p.ProtocolError):
            p.envelope(p.Kind.COMMAND, [], seq=1, stamp_us=0, sender="has space")
        with self.assertRaises(p.ProtocolError):
            p.mission_body(1, [p.Waypoint(0, 0)], arrival_radius=0)
        for late in (-1.0, 1e20):
            with self.assertRaises(p.ProtocolError):
                p.mission_body(1, [p.Waypoint(0, 0, time=late)])
        p.mission_body(1, [p.Waypoint(0, 0, time=p.MAX_WAYPOINT_TIME)])


if __name__ == "__main__":
    unittest.main()
