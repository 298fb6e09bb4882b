"""An ArduSub ROV as pymavlink speaks it, for the MAVLink medium's tests: an independent MAVLink
implementation on UDP loopback.

It listens on 127.0.0.1:PORT and sends, as system 1 component 1 in MAVLink 2, a HEARTBEAT each
second (MAV_TYPE_SUBMARINE, MAV_AUTOPILOT_ARDUPILOTMEGA, armed once commanded to) and ATTITUDE,
GLOBAL_POSITION_INT, SCALED_PRESSURE and SYS_STATUS five times a second, with fixed values, to the
address given with --to (as ArduSub sends to a ground station) and to every address that sent it
something (as a vehicle answers the ground stations that reach it). A COMMAND_LONG is answered with
a COMMAND_ACK (accepted) to all of them; MAV_CMD_COMPONENT_ARM_DISARM arms or disarms it.

It reports on stdout, one JSON object a line: `ready`, each sender's first `heartbeat` (its ids,
MAV_TYPE and autopilot), every `command`, and what it did when told on stdin:
  stop-heartbeat  sends no more heartbeats (the rest goes on); reports `heartbeat-stopped` with
                  how many seconds ago the last one went
  corrupt         sends one frame with a bad checksum, one of a message id no dialect has, one cut
                  off, and a datagram of garbage, each in a datagram of its own, then an ATTITUDE
                  whose time_boot_ms is 424242; reports `corrupt-sent`
  quit            ends

usage: mavlink_vehicle.py PORT SECONDS [--to HOST:PORT]"""
import json
import socket
import sys
import threading
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from pymavlink.generator.mavcrc import x25crc

port, seconds = int(sys.argv[1]), float(sys.argv[2])
fixed = []
if "--to" in sys.argv:
    host, to_port = sys.argv[sys.argv.index("--to") + 1].rsplit(":", 1)
    fixed.append((host, int(to_port)))

sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", port))
sock.settimeout(0.05)
mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
mav.robust_parsing = True
start = time.monotonic()
clients = []
commands = []
lock = threading.Lock()
state = {"armed": False, "heartbeat": True, "last_heartbeat": None}
heard = set()


def say(record):
    with lock:
        sys.stdout.write(json.dumps(record) + "\n")
        sys.stdout.flush()


def send(data):
    for addr in fixed + clients:
        try:
            sock.sendto(data, addr)
        except OSError:
            pass


def boot_ms():
    return int((time.monotonic() - start) * 1000)


def heartbeat():
    mode = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if state["armed"]:
        mode |= mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    # custom mode 19: ArduSub's MANUAL
    send(mav.heartbeat_encode(mavlink2.MAV_TYPE_SUBMARINE, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA,
                              mode, 19, mavlink2.MAV_STATE_ACTIVE).pack(mav))
    state["last_heartbeat"] = time.monotonic()


def attitude(t):
    return mav.attitude_encode(t, 0.1, -0.05, 1.57, 0.01, 0.0, -0.02).pack(mav)


def telemetry():
    t = boot_ms()
    send(attitude(t))
    send(mav.global_position_int_encode(t, 435081000, 164402000, -12500, -12500, 10, -5, 2,
                                        9000).pack(mav))
    send(mav.scaled_pressure_encode(t, 2250.5, 0.0, 1850).pack(mav))
    sensors = mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    send(mav.sys_status_encode(sensors, sensors, sensors, 250, 15800, 420, 76, 0, 0, 0, 0, 0,
                               0).pack(mav))


def with_crc(frame, extra):
    """The frame with its checksum made anew with CRC_EXTRA `extra`."""
    crc = x25crc(frame[1:-2])
    crc.accumulate(bytes([extra]))
    return frame[:-2] + crc.crc.to_bytes(2, "little")


def corrupt():
    # sequence numbers and times that hold no start marker (0xFD, 0xFE) where a cut frame ends
    mav.seq = 10
    bad_crc = bytearray(attitude(1000))
    bad_crc[-1] ^= 0xFF
    unknown = bytearray(attitude(1000))
    unknown[7:10] = (16000000).to_bytes(3, "little")
    unknown = with_crc(bytes(unknown), 0)
    cut = mav.global_position_int_encode(1000, 435081000, 164402000, -12500, -12500, 10, -5, 2,
                                         9000).pack(mav)[:14]
    assert not any(b in (0xFD, 0xFE) for b in cut[1:]), cut
    for data in (bytes(bad_crc), unknown, cut, b"garbage between frames"):
        send(data)
    send(attitude(424242))
    say({"event": "corrupt-sent", "count": 4})


def handle(msg, addr):
    kind = msg.get_type()
    if kind == "BAD_DATA":
        return
    sender = (msg.get_srcSystem(), msg.get_srcComponent())
    if kind == "HEARTBEAT" and sender not in heard:
        heard.add(sender)
        say({"event": "heartbeat", "sysid": sender[0], "compid": sender[1], "type": msg.type,
             "autopilot": msg.autopilot})
    if kind == "COMMAND_LONG":
        say({"event": "command", "sysid": sender[0], "compid": sender[1],
             "command": msg.command, "target_system": msg.target_system,
             "target_component": msg.target_component, "param1": msg.param1})
        if msg.command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM:
            state["armed"] = msg.param1 == 1.0
        send(mav.command_ack_encode(msg.command, mavlink2.MAV_RESULT_ACCEPTED, 0, 0,
                                    sender[0], sender[1]).pack(mav))


def orders():
    for line in sys.stdin:
        with lock:
            commands.append(line.strip())


threading.Thread(target=orders, daemon=True).start()
say({"event": "ready", "port": port})
next_heartbeat = next_telemetry = time.monotonic()
deadline = time.monotonic() + seconds
while time.monotonic() < deadline:
    now = time.monotonic()
    if state["heartbeat"] and now >= next_heartbeat:
        heartbeat()
        next_heartbeat = now + 1.0
    if now >= next_telemetry:
        telemetry()
        next_telemetry = now + 0.2
    with lock:
        todo, commands[:] = list(commands), []
    for order in todo:
        if order == "stop-heartbeat":
            state["heartbeat"] = False
            say({"event": "heartbeat-stopped",
                 "since_last": time.monotonic() - state["last_heartbeat"]})
        elif order == "corrupt":
            corrupt()
        elif order == "quit":
            deadline = 0
    try:
        data, addr = sock.recvfrom(65536)
    except socket.timeout:
        continue
    if addr not in clients and addr not in fixed and len(clients) < 16:
        clients.append(addr)
    for msg in mav.parse_buffer(data) or []:
        handle(msg, addr)
