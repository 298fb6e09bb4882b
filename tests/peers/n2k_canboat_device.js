// An NMEA 2000 device played by canboat's own JavaScript implementation (@canboat/canboatjs): its
// `N2kDevice` — the address claim signalk-server uses (ISO Request, ISO Address Claim, the
// lower NAME keeping an address, the higher moving to the next free one) — on a CAN bus whose
// frames are slcan lines on standard input and output (`T` + 8 hex digits of identifier + length
// + data), so that a test can wire it to other devices without SocketCAN.
//
//   node n2k_canboat_device.js PREFERRED_ADDRESS UNIQUE_NUMBER SECONDS
//
// Frames heard are parsed with canboatjs's `FromPgn` and handed to the device; the frames the
// device sends are encoded with `pgnToCandump3`. Once it holds an address it also sends a vessel
// heading every 300 ms. Besides frames it prints JSON lines: {"event": "address", "address": …,
// "cansend": …} whenever either changes.

"use strict";

const readline = require("readline");
const { FromPgn, N2kDevice, pgnToCandump3 } = require("@canboat/canboatjs");

const [preferred, unique, seconds] = process.argv.slice(2).map(Number);
if (!Number.isInteger(preferred) || !Number.isInteger(unique) || !(seconds > 0)) {
  console.error("usage: node n2k_canboat_device.js PREFERRED_ADDRESS UNIQUE_NUMBER SECONDS");
  process.exit(2);
}

/** The slcan line of a candump line `(time) bus ID#DATA`. */
function slcanLine(candump) {
  const [id, data] = candump.trim().split(" ")[2].split("#");
  return `T${id.padStart(8, "0").toUpperCase()}${data.length / 2}${data.toUpperCase()}`;
}

class LineDevice extends N2kDevice {
  sendPGN(pgn, src = undefined) {
    const msg = JSON.parse(JSON.stringify(pgn));
    msg.src = src === undefined ? this.address : src;
    if (msg.prio === undefined) msg.prio = 3;
    if (msg.dst === undefined) msg.dst = 255;
    const lines = pgnToCandump3(msg) || [];
    for (const l of lines) process.stdout.write(slcanLine(l) + "\n");
  }
}

const device = new LineDevice(
  {
    preferredAddress: preferred,
    uniqueNumber: unique,
    addressClaimDetectionTime: 400,
    disableDefaultTransmitPGNs: true,
  },
  "n2k-test-device",
);
const parser = new FromPgn({});
parser.on("error", () => {});

const input = readline.createInterface({ input: process.stdin });
input.on("line", (line) => {
  const m = /^T([0-9A-Fa-f]{8})([0-8])([0-9A-Fa-f]*)$/.exec(line.trim());
  if (!m) return;
  const pgn = parser.parseString(`(0.000000) can0 ${m[1]}#${m[3].slice(0, 2 * Number(m[2]))}`);
  if (pgn) device.n2kMessage(pgn);
});
input.on("close", () => process.exit(0));

let shown = "";
setInterval(() => {
  const now = JSON.stringify({ event: "address", address: device.address, cansend: device.cansend });
  if (now !== shown) {
    shown = now;
    process.stdout.write(now + "\n");
  }
  if (device.cansend) {
    device.sendPGN({ pgn: 127250, prio: 2, dst: 255, fields: { sid: 1, heading: 1.0, reference: "True" } });
  }
}, 300);

device.start();
setTimeout(() => process.exit(0), seconds * 1000);
