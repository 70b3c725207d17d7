"""Message signing (docs/protocol.md, *Signing*): HMAC-SHA-256 tags, key
files from ``mech-gcs keygen``, and the freshness rule for what the router
signs for us.

A tag is bin 8 of 29 bytes replacing the envelope's final ``nil``::

    key_id   4 bytes  SHA-256(secret)[0:4]
    link     1 byte   bit 7 set when the router signed it; bits 0-6 link number
    stamp_us 8 bytes  big-endian station time, rising per stream
    mac     16 bytes  HMAC-SHA-256(secret, region || key_id || link || stamp)[0:16]
"""

from __future__ import annotations

import hashlib
import hmac
import os
import stat
import struct
from collections import deque
from dataclasses import dataclass
from typing import Deque, Optional, Tuple

TAG_LEN = 29
"""Length of a tag's payload (the bin 8 header ``c4 1d`` comes before it)."""

ROUTER_BIT = 0x80
"""Link byte bit set on everything the router signs."""

WINDOW_MESSAGES = 64
"""A stamp may be this many accepted messages behind the newest..."""

WINDOW_US = 1_000_000
"""...and at most this far (µs) behind it."""


class KeyFileError(ValueError):
    """A key file that cannot be used."""


@dataclass(frozen=True)
class Key:
    """A 256-bit key and the name it signs as."""

    name: str
    secret: bytes

    def __post_init__(self) -> None:
        if len(self.secret) != 32:
            raise KeyFileError("a key is 32 bytes (64 hex digits)")

    @property
    def key_id(self) -> bytes:
        """The 4-byte key id: the first bytes of SHA-256(secret)."""
        return hashlib.sha256(self.secret).digest()[:4]

    def mac(self, region: bytes, head: bytes) -> bytes:
        """The 16-byte MAC over the signed region and the tag's head."""
        return hmac.new(self.secret, region + head, hashlib.sha256).digest()[:16]

    def seal(self, region: bytes, stamp_us: int, link: int = 0) -> bytes:
        """The whole signed message: ``region`` (the message without its
        final nil) followed by the tag."""
        head = self.key_id + bytes([link & 0xFF]) + struct.pack(">Q", stamp_us)
        return region + b"\xc4\x1d" + head + self.mac(region, head)

    def open(self, message: bytes) -> Optional[Tuple[int, int]]:
        """Checks a signed message's tag; returns ``(link, stamp_us)`` when
        it was made with this key, else ``None``. Compares in constant time."""
        if len(message) < TAG_LEN + 2 or message[-TAG_LEN - 2 : -TAG_LEN] != b"\xc4\x1d":
            return None
        region, tag = message[: -TAG_LEN - 2], message[-TAG_LEN:]
        head, mac = tag[:13], tag[13:]
        if not hmac.compare_digest(head[:4], self.key_id):
            return None
        if not hmac.compare_digest(mac, self.mac(region, head)):
            return None
        return head[4], struct.unpack(">Q", head[5:13])[0]


def parse_key(text: str) -> Key:
    """Reads the text of a key file: ``name = "..."`` and
    ``secret = "<64 hex digits>"`` lines, ``#`` comments."""
    fields = {}
    for n, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if "=" not in line:
            raise KeyFileError(f'line {n}: expected key = "value"')
        k, v = (p.strip() for p in line.split("=", 1))
        if len(v) < 2 or v[0] != '"' or v[-1] != '"':
            raise KeyFileError(f"line {n}: the value must be quoted")
        fields[k] = v[1:-1]
    if "name" not in fields or "secret" not in fields:
        raise KeyFileError("a key file has a name and a secret")
    try:
        secret = bytes.fromhex(fields["secret"])
    except ValueError as e:
        raise KeyFileError(f"secret: {e}") from e
    return Key(fields["name"], secret)


def read_key(path: str) -> Key:
    """Reads a key file written by ``mech-gcs keygen``. Like the station and
    the agent, refuses a file that other users can read."""
    if os.name == "posix":
        mode = os.stat(path).st_mode
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            raise KeyFileError(
                f"{path} can be read by other users (mode {mode & 0o777:o}); chmod 600 it"
            )
    with open(path, encoding="utf-8") as f:
        return parse_key(f.read())


class Freshness:
    """The receiving side of one stream (what the router signs for us):
    each stamp is accepted once, never more than 64 messages or 1 s behind
    the newest accepted, so a replayed or duplicated message is refused
    while one the network delivered a little late is not lost."""

    def __init__(self) -> None:
        self._newest: Optional[int] = None
        self._recent: Deque[int] = deque(maxlen=WINDOW_MESSAGES)

    def accept(self, stamp_us: int) -> bool:
        """Whether ``stamp_us`` is fresh; records it if so."""
        newest = self._newest
        if newest is not None:
            if stamp_us in self._recent:
                return False
            if stamp_us < newest:
                behind = sum(1 for s in self._recent if s > stamp_us)
                if newest - stamp_us > WINDOW_US or behind >= WINDOW_MESSAGES:
                    return False
        self._recent.append(stamp_us)
        self._newest = stamp_us if newest is None else max(newest, stamp_us)
        return True
