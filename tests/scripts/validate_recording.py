"""Validates every message of every JSON channel of a MECH recording
against the JSON Schema the file itself embeds for that channel, with
Python's `jsonschema` (draft 2020-12) and `mcap` packages: independent of
MECH's own code. Prints one JSON object: messages validated per topic,
`/mech/events` and `/mech/snapshot` messages per event name, channels
without a schema, and the first errors (topic, message, path, reason)."""

import json
import sys

from jsonschema import Draft202012Validator
from mcap.reader import make_reader


def main(path):
    validators = {}
    validated = {}
    events = {}
    unchecked = {}
    errors = []
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            topic = channel.topic
            if schema is None or schema.encoding != "jsonschema":
                unchecked[topic] = unchecked.get(topic, 0) + 1
                continue
            validator = validators.get(schema.id)
            if validator is None:
                document = json.loads(schema.data)
                Draft202012Validator.check_schema(document)
                validator = validators[schema.id] = Draft202012Validator(document)
            data = json.loads(message.data)
            validated[topic] = validated.get(topic, 0) + 1
            if topic in ("/mech/events", "/mech/snapshot"):
                name = data.get("event")
                events[name] = events.get(name, 0) + 1
            for e in validator.iter_errors(data):
                if len(errors) < 20:
                    errors.append(
                        {
                            "topic": topic,
                            "message": data,
                            "path": "/".join(str(p) for p in e.absolute_path),
                            "reason": e.message[:300],
                        }
                    )
    print(
        json.dumps(
            {
                "validated": validated,
                "events": events,
                "unchecked": unchecked,
                "errors": errors,
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1])
