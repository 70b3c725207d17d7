"""Reads a MECH recording with the `mcap` package from PyPI, independently
of MECH's own reader, and prints what it holds as one JSON object: the
header profile, each topic's schema, encoding and message count (counted by
iterating every message), the first message of each JSON topic, the
summary's statistics and the metadata records. Every JSON message must
parse."""

import json
import sys

from mcap.reader import make_reader


def main(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        topics = {}
        for schema, channel, message in reader.iter_messages():
            t = topics.setdefault(
                channel.topic,
                {
                    "schema": schema.name if schema else None,
                    "schema_encoding": schema.encoding if schema else None,
                    "encoding": channel.message_encoding,
                    "count": 0,
                },
            )
            t["count"] += 1
            if channel.message_encoding == "json":
                parsed = json.loads(message.data)
                t.setdefault("first", parsed)
        stats = reader.get_summary().statistics
        print(
            json.dumps(
                {
                    "profile": reader.get_header().profile,
                    "topics": topics,
                    "message_count": stats.message_count,
                    "metadata": {m.name: dict(m.metadata) for m in reader.iter_metadata()},
                }
            )
        )


if __name__ == "__main__":
    main(sys.argv[1])
