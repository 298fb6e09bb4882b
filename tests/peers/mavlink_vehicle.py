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

The command line, socket, stdin orders and main loop are mavlink_peer.py's.

usage: mavlink_vehicle.py PORT SECONDS [--to HOST:PORT]"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from mavlink_peer import Peer  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink2  # noqa: E402
from pymavlink.generator.mavcrc import x25crc  # noqa: E402

peer = Peer(receive_timeout=0.05)
mav = peer.mav
state = {"armed": False}
heard = set()


def heartbeat():
    mode = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if state["armed"]:
        mode |= mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    # custom mode 19: ArduSub's MANUAL
    return mav.heartbeat_encode(mavlink2.MAV_TYPE_SUBMARINE, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                mode, 19, mavlink2.MAV_STATE_ACTIVE).pack(mav)


def attitude(t):
    return mav.attitude_encode(t, 0.1, -0.05, 1.57, 0.01, 0.0, -0.02).pack(mav)


def telemetry():
    t = peer.boot_ms()
    peer.send(attitude(t))
    peer.send(mav.global_position_int_encode(t, 435081000, 164402000, -12500, -12500, 10, -5, 2,
                                             9000).pack(mav))
    peer.send(mav.scaled_pressure_encode(t, 2250.5, 0.0, 1850).pack(mav))
    sensors = mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    peer.send(mav.sys_status_encode(sensors, sensors, sensors, 250, 15800, 420, 76, 0, 0, 0, 0, 0,
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
        peer.send(data)
    peer.send(attitude(424242))
    peer.say({"event": "corrupt-sent", "count": 4})


def handle(msg):
    kind = msg.get_type()
    sender = (msg.get_srcSystem(), msg.get_srcComponent())
    if kind == "HEARTBEAT" and sender not in heard:
        heard.add(sender)
        peer.say({"event": "heartbeat", "sysid": sender[0], "compid": sender[1],
                  "type": msg.type, "autopilot": msg.autopilot})
    if kind == "COMMAND_LONG":
        peer.say({"event": "command", "sysid": sender[0], "compid": sender[1],
                  "command": msg.command, "target_system": msg.target_system,
                  "target_component": msg.target_component, "param1": msg.param1})
        if msg.command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM:
            state["armed"] = msg.param1 == 1.0
        peer.send(mav.command_ack_encode(msg.command, mavlink2.MAV_RESULT_ACCEPTED, 0, 0,
                                         sender[0], sender[1]).pack(mav))


peer.run(heartbeat, telemetry, handle, {"corrupt": corrupt})
