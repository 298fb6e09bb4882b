"""A Zenoh router (Python eclipse-zenoh) that seabus nodes reach as clients: it listens on the
endpoints given, prints `ready` once it does, and routes until it is killed or SECONDS have passed.
Started again on the same endpoints, it waits (at most 10 s) for them to be free.

usage: zenoh_router.py ENDPOINT[,ENDPOINT...] SECONDS"""
import json
import sys
import time

import zenoh

endpoints, seconds = sys.argv[1].split(","), float(sys.argv[2])
conf = zenoh.Config()
conf.insert_json5("mode", '"router"')
conf.insert_json5("listen/endpoints", json.dumps(endpoints))
conf.insert_json5("scouting/multicast/enabled", "false")

session = None
for attempt in range(40):
    try:
        session = zenoh.open(conf)
        break
    except zenoh.ZError as e:
        print(json.dumps({"retry": attempt, "error": str(e)}), file=sys.stderr, flush=True)
        time.sleep(0.25)
if session is None:
    sys.exit("cannot listen on " + ", ".join(endpoints))
print("ready", flush=True)
time.sleep(seconds)
session.close()
