"""An NMEA 2000 device played by the Python `nmea2000` package (its encoder and decoder, built on
canboat's database), as the slcan host of a serial port or pseudo-terminal adapter.

    python3 n2k_python.py read PORT SECONDS
    python3 n2k_python.py write PORT SECONDS < messages.json

`read` opens the channel (C, S5, O: 250 kbit/s), hands every extended frame the adapter passes to
`NMEA2000Decoder` as a candump line (its fast-packet reassembly and field decoder) and prints a
JSON line per PGN: {"pgn": …, "id": …, "src": …, "dst": …, "prio": …, "fields": {id: value}}
(canboat's units: radians, kelvin; fields without a value and reserved ones left out).

`write` reads a JSON list on its first line of standard input — [{"pgn": 127250, "id":
"vesselHeading", "prio": 2, "src": 35, "fields": {…}}, …] in canboat's units — encodes each with
`create_encoder("candump3")` and sends the frames as slcan lines every 300 ms, printing
{"event": "round", "n": …} after each round.

Both stop after SECONDS, or when standard input ends.
"""

import json
import os
import select
import sys
import time

from nmea2000 import NMEA2000Decoder, NMEA2000Field, NMEA2000Message, create_encoder


def slcan_line(candump: str) -> bytes:
    """The slcan line of a candump line `(time) bus ID#DATA`."""
    frame = candump.strip().split(" ")[2]
    can_id, data = frame.split("#")
    return f"T{can_id.zfill(8).upper()}{len(data) // 2}{data.upper()}\r".encode()


def plain(value):
    """A JSON-able value."""
    if isinstance(value, (int, float, str, bool)) or value is None:
        return value
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    return str(value)


def read(fd: int, seconds: float) -> None:
    decoder = NMEA2000Decoder(units="native")
    deadline = time.monotonic() + seconds
    buffer = b""
    while time.monotonic() < deadline:
        ready, _, _ = select.select([fd, sys.stdin], [], [], 0.1)
        if sys.stdin in ready and not sys.stdin.readline():
            return
        if fd not in ready:
            continue
        buffer += os.read(fd, 4096)
        *lines, buffer = buffer.replace(b"\n", b"\r").split(b"\r")
        if len(buffer) > 4096:
            buffer = b""
        for raw in lines:
            line = raw.lstrip(b"\x07zZ").decode("latin1")
            if len(line) < 10 or line[0] != "T":
                continue
            can_id, length, data = line[1:9], int(line[9]), line[10:]
            try:
                msg = decoder.decode(f"(0.000000) can0 {can_id}#{data[: 2 * length]}")
            except Exception as e:  # a frame it cannot take is reported, not fatal
                print(json.dumps({"event": "error", "line": line, "error": str(e)}), flush=True)
                continue
            if msg is None:
                continue
            fields = {
                f.id: plain(f.value)
                for f in msg.fields
                if f.value is not None and not f.id.startswith("reserved")
            }
            print(
                json.dumps(
                    {
                        "event": "pgn",
                        "pgn": msg.PGN,
                        "id": msg.id,
                        "src": msg.source,
                        "dst": msg.destination,
                        "prio": msg.priority,
                        "fields": fields,
                    }
                ),
                flush=True,
            )


def write(fd: int, seconds: float) -> None:
    messages = json.loads(sys.stdin.readline())
    encoder = create_encoder("candump3")
    lines = []
    for m in messages:
        msg = NMEA2000Message(
            PGN=m["pgn"],
            id=m["id"],
            priority=m["prio"],
            source=m["src"],
            destination=m.get("dst", 255),
            fields=[NMEA2000Field(id=k, value=v) for k, v in m["fields"].items()],
        )
        out = encoder.encode(msg)
        lines.extend(slcan_line(c) for c in ([out] if isinstance(out, str) else out))
    deadline = time.monotonic() + seconds
    n = 0
    while time.monotonic() < deadline:
        for line in lines:
            os.write(fd, line)
        n += 1
        print(json.dumps({"event": "round", "n": n}), flush=True)
        ready, _, _ = select.select([fd, sys.stdin], [], [], 0.3)
        if fd in ready:
            os.read(fd, 4096)  # the adapter's answers, left
        if sys.stdin in ready and not sys.stdin.readline():
            return


def main() -> int:
    if len(sys.argv) != 4 or sys.argv[1] not in ("read", "write"):
        print(__doc__, file=sys.stderr)
        return 2
    mode, port, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY)
    os.write(fd, b"C\rS5\rO\r")
    print(json.dumps({"event": "open"}), flush=True)
    try:
        (read if mode == "read" else write)(fd, seconds)
    finally:
        try:
            os.write(fd, b"C\r")
        except OSError:
            pass
        os.close(fd)
    return 0


if __name__ == "__main__":
    sys.exit(main())
