"""What the pymavlink vehicles of the tests (mavlink_vehicle.py, mavlink_ardusub.py) share: their
command line, their UDP socket, their reports on stdout, the orders they read on stdin and their
main loop.

A vehicle is run as `SCRIPT PORT SECONDS [--to HOST:PORT]`. It listens on 127.0.0.1:PORT and
sends, as system 1 component 1 in MAVLink 2, to the address given with --to and to every address
that sent it something (up to 16): a HEARTBEAT each second while heartbeats are on, its telemetry
five times a second. Every message it receives, but for bad data, goes to its handler.

It reports on stdout, one JSON object a line: `ready`, then what the vehicle says. Orders on
stdin, one a line, that every vehicle takes:
  stop-heartbeat  sends no more heartbeats (the rest goes on); reports `heartbeat-stopped` with
                  how many seconds ago the last one went
  quit            ends
and those of the vehicle's own."""
import json
import socket
import sys
import threading
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink2


class Peer:
    """A vehicle on UDP loopback, from the command line; `receive_timeout` is how long the main
    loop waits for a datagram before it looks at the clock again."""

    def __init__(self, receive_timeout):
        self.port, self.seconds = int(sys.argv[1]), float(sys.argv[2])
        self.fixed = []
        if "--to" in sys.argv:
            host, to_port = sys.argv[sys.argv.index("--to") + 1].rsplit(":", 1)
            self.fixed.append((host, int(to_port)))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", self.port))
        self.sock.settimeout(receive_timeout)
        self.mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        self.mav.robust_parsing = True
        self.start = time.monotonic()
        self.clients = []
        self.orders_in = []
        self.lock = threading.Lock()
        self.heartbeat_on = True
        self.last_heartbeat = None

    def say(self, record):
        """Reports `record` on stdout as a line of JSON."""
        with self.lock:
            sys.stdout.write(json.dumps(record) + "\n")
            sys.stdout.flush()

    def send(self, data):
        """Sends `data` to the --to address and to every address heard from."""
        for addr in self.fixed + self.clients:
            try:
                self.sock.sendto(data, addr)
            except OSError:
                pass

    def boot_ms(self):
        """Milliseconds since the vehicle started, as its messages' time_boot_ms."""
        return int((time.monotonic() - self.start) * 1000)

    def send_heartbeat(self, heartbeat):
        """Sends the HEARTBEAT `heartbeat` (packed), noting when."""
        self.send(heartbeat)
        self.last_heartbeat = time.monotonic()

    def _read_orders(self):
        for line in sys.stdin:
            with self.lock:
                self.orders_in.append(line.strip())

    def run(self, heartbeat, telemetry, handle, orders=None):
        """Runs the vehicle for SECONDS or until `quit`: `heartbeat()` gives the HEARTBEAT to send
        (packed), `telemetry()` sends the rest, `handle(msg)` takes each message received and
        `orders` maps the vehicle's own orders to what does them."""
        orders = orders or {}
        threading.Thread(target=self._read_orders, daemon=True).start()
        self.say({"event": "ready", "port": self.port})
        next_heartbeat = next_telemetry = time.monotonic()
        deadline = time.monotonic() + self.seconds
        while time.monotonic() < deadline:
            now = time.monotonic()
            if self.heartbeat_on and now >= next_heartbeat:
                self.send_heartbeat(heartbeat())
                next_heartbeat = now + 1.0
            if now >= next_telemetry:
                telemetry()
                next_telemetry = now + 0.2
            with self.lock:
                todo, self.orders_in[:] = list(self.orders_in), []
            for order in todo:
                if order == "stop-heartbeat":
                    self.heartbeat_on = False
                    self.say({"event": "heartbeat-stopped",
                              "since_last": time.monotonic() - self.last_heartbeat})
                elif order == "quit":
                    deadline = 0
                elif order in orders:
                    orders[order]()
            try:
                data, addr = self.sock.recvfrom(65536)
            except socket.timeout:
                continue
            if addr not in self.clients and addr not in self.fixed and len(self.clients) < 16:
                self.clients.append(addr)
            for msg in self.mav.parse_buffer(data) or []:
                if msg.get_type() != "BAD_DATA":
                    handle(msg)
