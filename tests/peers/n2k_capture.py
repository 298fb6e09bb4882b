"""Plays a candump capture of an NMEA 2000 network (canboat's samples) into an slcan adapter with
python-can, frame by frame as recorded, and writes the same frames in canboat's PLAIN format (one
line per frame: time, priority, PGN, source, destination, length, bytes) for canboat's analyzer.

Reads both candump forms canboat's samples use: `<0x18eeff01> [8] 05 a0 …` and
`(1502984866.421964) slcan0 09F112CC#FF725AFF7FFF7FFD`.

Usage: n2k_capture.py CAPTURE PLAIN_OUT [SLCAN_PORT]  (without a port: only the PLAIN file)
Prints `sent N` when done.
"""
import re
import sys
import time

OLD = re.compile(r"^<0x([0-9a-fA-F]+)> \[(\d)\]((?: [0-9a-fA-F]{2})*)\s*$")
LOG = re.compile(r"^\(([\d.]+)\) \S+ ([0-9A-Fa-f]{8})#([0-9A-Fa-f]*)$")


def frames(path):
    for line in open(path):
        line = line.strip()
        m = OLD.match(line)
        if m:
            yield int(m.group(1), 16), bytes.fromhex(m.group(3).replace(" ", ""))
            continue
        m = LOG.match(line)
        if m:
            yield int(m.group(2), 16), bytes.fromhex(m.group(3))


def plain(can_id, data):
    """The frame in canboat's PLAIN format (ISO 11783's identifier taken apart)."""
    prio = (can_id >> 26) & 7
    dp = (can_id >> 24) & 3
    pf = (can_id >> 16) & 0xFF
    ps = (can_id >> 8) & 0xFF
    src = can_id & 0xFF
    if pf < 240:
        pgn, dst = (dp << 16) | (pf << 8), ps
    else:
        pgn, dst = (dp << 16) | (pf << 8) | ps, 255
    return "2017-01-01T00:00:00.000Z,%d,%d,%d,%d,%d,%s" % (
        prio, pgn, src, dst, len(data), ",".join("%02x" % b for b in data))


def main():
    capture, out = sys.argv[1], sys.argv[2]
    listed = list(frames(capture))
    with open(out, "w") as f:
        for can_id, data in listed:
            f.write(plain(can_id, data) + "\n")
    if len(sys.argv) > 3:
        import can
        bus = can.Bus(interface="slcan", channel=sys.argv[3], bitrate=250000, sleep_after_open=0)
        for i, (can_id, data) in enumerate(listed):
            bus.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=True))
            # a 250 kbit/s network's pace, roughly: the adapter's line is never the bottleneck
            if i % 50 == 49:
                time.sleep(0.01)
        bus.shutdown()
    print("sent", len(listed), flush=True)


main()
