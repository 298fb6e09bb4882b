"""An independent Zenoh program (Python eclipse-zenoh) standing for a shore tool: it connects to
a seabus vehicle, reads its data as JSON, sends it a course command and reports, one JSON line
each, what it read and what became of the command.

usage: zenoh_peer.py ENDPOINT PREFIX SECONDS"""
import json
import sys
import threading
import time

import zenoh

endpoint, prefix, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
conf = zenoh.Config()
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
conf.insert_json5("scouting/multicast/enabled", "false")
lock = threading.Lock()
latest = {}


def say(record):
    # one whole line at a time: the subscriber's thread and the main loop both print
    with say_lock:
        sys.stdout.write(json.dumps(record) + "\n")
        sys.stdout.flush()


say_lock = threading.Lock()


def heard(sample):
    key = str(sample.key_expr)
    try:
        value = json.loads(sample.payload.to_string())
    except ValueError:
        return
    with lock:
        first = key not in latest
        latest[key] = value
    if first or key.endswith("/cmd/status"):
        say({"key": key, "encoding": str(sample.encoding), "value": value})


with zenoh.open(conf) as session:
    sub = session.declare_subscriber(prefix + "/**", heard)
    deadline = time.time() + seconds
    # the command goes once the vehicle's position has been read, and again each second until
    # the vehicle says what became of it
    sent = 0
    while time.time() < deadline:
        with lock:
            ready = prefix + "/nav/position" in latest
            status = latest.get(prefix + "/cmd/status")
        if status and status.get("state") not in (None, "pending"):
            break
        if ready:
            course = {"heading": 90.0, "depth": 2.0, "speed": 1.2}
            session.put(prefix + "/cmd/course", json.dumps(course),
                        encoding=zenoh.Encoding.APPLICATION_JSON.with_schema("command"))
            sent += 1
            say({"sent": course, "count": sent})
            time.sleep(1.0)
        else:
            time.sleep(0.1)
    sub.undeclare()
