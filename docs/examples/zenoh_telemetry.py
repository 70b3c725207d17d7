"""Reads MECH robots from Zenoh without MECH's code: what each station
says its robots are, then one line per telemetry sample and per robot
that appears or is lost (schema: docs/zenoh.md).

    pip install eclipse-zenoh
    python3 zenoh_telemetry.py [ENDPOINT] [STATION] [SAMPLES]
"""
import json, sys, threading
import zenoh

endpoint = sys.argv[1] if len(sys.argv) > 1 else "tcp/127.0.0.1:7447"
station = sys.argv[2] if len(sys.argv) > 2 else "*"        # "*": every station
samples = int(sys.argv[3]) if len(sys.argv) > 3 else 0     # 0: until Ctrl-C

conf = zenoh.Config()
conf.insert_json5("mode", '"client"')                      # connects; listens nowhere
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
conf.insert_json5("scouting/multicast/enabled", "false")
seen, enough = 0, threading.Event()

def telemetry(sample):
    global seen
    t = json.loads(sample.payload.to_bytes())              # SI units, REP 103
    p = t["pose"]
    print(f'{t["station"]}/{t["robot"]} x={p["x"]:.2f} y={p["y"]:.2f} '
          f'heading={p["heading"]:.2f} mode={t["mode"]} channel={t["channel"]}', flush=True)
    seen += 1
    if samples and seen >= samples:
        enough.set()

def alive(sample):                                          # mech/<station>/<robot>
    state = "appeared" if sample.kind == zenoh.SampleKind.PUT else "lost"
    print(f"{sample.key_expr} {state}", flush=True)

with zenoh.open(conf) as session:
    for reply in session.get(f"mech/{station}/*/info"):     # the robots now
        if reply.ok:
            info = json.loads(reply.ok.payload.to_bytes())
            print(f'{info["station"]}/{info["robot"]} is a {info["platform"]}', flush=True)
    live = session.liveliness().declare_subscriber(f"mech/{station}/*", alive, history=True)
    sub = session.declare_subscriber(f"mech/{station}/*/telemetry", telemetry)
    enough.wait(timeout=30 if samples else None)
sys.exit(0 if not samples or seen >= samples else 1)
