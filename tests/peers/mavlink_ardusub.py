"""An ArduSub ROV as pymavlink speaks it, for the MAVLink driver's tests: an independent MAVLink
implementation on UDP loopback that answers commands as ArduSub does.

It listens on 127.0.0.1:PORT and sends, as system 1 component 1 in MAVLink 2, to the address given
with --to and to every address that sent it something:
  HEARTBEAT each second (MAV_TYPE_SUBMARINE, MAV_AUTOPILOT_ARDUPILOTMEGA, its custom mode and
  armed flag, MAV_STATE_STANDBY disarmed, MAV_STATE_ACTIVE armed);
  five times a second ATTITUDE (roll 0.1, pitch -0.05, yaw -1.57 rad; rates 0.01, 0, -0.02 rad/s),
  GLOBAL_POSITION_INT (43.5081, 16.4402; alt and relative_alt -12500 mm; vx 30, vy -40, vz 2
  cm/s; hdg UINT16_MAX, unknown), SCALED_PRESSURE (2250.5 hPa, 18.5 degC), SCALED_PRESSURE2 (the
  external depth sensor: 1515.0 hPa, 16.25 degC) and SYS_STATUS
  (15800 mV, current -1 unknown, 76 %).

Commands (COMMAND_LONG), answered with a COMMAND_ACK as ArduSub would:
  MAV_CMD_COMPONENT_ARM_DISARM  arms or disarms: ACCEPTED
  MAV_CMD_DO_SET_MODE           custom mode param2: ACCEPTED for MANUAL (19), STABILIZE (0),
                                DEPTH_HOLD (2), POSHOLD (16) and GUIDED (4); AUTO (3) is DENIED (no
                                position estimate); any other number is UNSUPPORTED
  anything else                 UNSUPPORTED
After the order `mute`, commands are reported but not answered.

It reports on stdout, one JSON object a line: `ready`; each `command` (with its confirmation and
params); each `manual` (MANUAL_CONTROL: target, x, y, z, r, buttons, and `t`, seconds since it
started); each `target` (SET_POSITION_TARGET_GLOBAL_INT); and what it did when told on stdin:
  stop-heartbeat  sends no more heartbeats (telemetry goes on); reports `heartbeat-stopped`
  mute            answers no more commands; reports `muted`
  quit            ends

The command line, socket, stdin orders and main loop are mavlink_peer.py's.

usage: mavlink_ardusub.py PORT SECONDS --to HOST:PORT"""
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from mavlink_peer import Peer  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink2  # noqa: E402

peer = Peer(receive_timeout=0.02)
if not peer.fixed:
    sys.exit(__doc__)
mav = peer.mav
state = {"armed": False, "mode": 19, "muted": False}
ACCEPTED_MODES = {19, 0, 2, 16, 4}
DENIED_MODES = {3}


def heartbeat():
    flags = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if state["armed"]:
        flags |= mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    status = mavlink2.MAV_STATE_ACTIVE if state["armed"] else mavlink2.MAV_STATE_STANDBY
    return mav.heartbeat_encode(mavlink2.MAV_TYPE_SUBMARINE, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                flags, state["mode"], status).pack(mav)


def telemetry():
    t = peer.boot_ms()
    peer.send(mav.attitude_encode(t, 0.1, -0.05, -1.57, 0.01, 0.0, -0.02).pack(mav))
    peer.send(mav.global_position_int_encode(t, 435081000, 164402000, -12500, -12500, 30, -40, 2,
                                             65535).pack(mav))
    peer.send(mav.scaled_pressure_encode(t, 2250.5, 0.0, 1850).pack(mav))
    # a BlueROV2's external depth sensor (Bar30) reports on the second pressure message
    peer.send(mav.scaled_pressure2_encode(t, 1515.0, 0.0, 1625).pack(mav))
    sensors = mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    peer.send(mav.sys_status_encode(sensors, sensors, sensors, 250, 15800, -1, 76, 0, 0, 0, 0, 0,
                                    0).pack(mav))


def answer(msg):
    """The result ArduSub gives a COMMAND_LONG, and what it does."""
    if msg.command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM:
        state["armed"] = msg.param1 == 1.0
        return mavlink2.MAV_RESULT_ACCEPTED
    if msg.command == mavlink2.MAV_CMD_DO_SET_MODE:
        mode = int(msg.param2)
        if mode in ACCEPTED_MODES:
            state["mode"] = mode
            return mavlink2.MAV_RESULT_ACCEPTED
        if mode in DENIED_MODES:
            return mavlink2.MAV_RESULT_DENIED
    return mavlink2.MAV_RESULT_UNSUPPORTED


def handle(msg):
    kind = msg.get_type()
    sender = (msg.get_srcSystem(), msg.get_srcComponent())
    if kind == "COMMAND_LONG":
        peer.say({"event": "command", "sysid": sender[0], "compid": sender[1],
                  "command": msg.command, "confirmation": msg.confirmation,
                  "target_system": msg.target_system, "target_component": msg.target_component,
                  "param1": msg.param1, "param2": msg.param2})
        if state["muted"]:
            return
        result = answer(msg)
        peer.send(mav.command_ack_encode(msg.command, result, 0, 0, sender[0],
                                         sender[1]).pack(mav))
        # ArduPilot says its new state at once
        if peer.heartbeat_on and result == mavlink2.MAV_RESULT_ACCEPTED:
            peer.send_heartbeat(heartbeat())
    elif kind == "MANUAL_CONTROL":
        peer.say({"event": "manual", "target": msg.target, "x": msg.x, "y": msg.y, "z": msg.z,
                  "r": msg.r, "buttons": msg.buttons, "t": time.monotonic() - peer.start})
    elif kind == "SET_POSITION_TARGET_GLOBAL_INT":
        peer.say({"event": "target", "frame": msg.coordinate_frame, "type_mask": msg.type_mask,
                  "alt": msg.alt, "vx": msg.vx, "vy": msg.vy, "yaw": msg.yaw})


def mute():
    state["muted"] = True
    peer.say({"event": "muted"})


peer.run(heartbeat, telemetry, handle, {"mute": mute})
