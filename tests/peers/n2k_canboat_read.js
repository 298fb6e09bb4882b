// An NMEA 2000 listener played by canboat's own JavaScript implementation (@canboat/canboatjs):
// it opens a serial port or pseudo-terminal as the host of an slcan adapter (C, S5, O: 250 kbit/s),
// turns every extended frame the adapter passes into a candump line and hands it to canboatjs's
// parser (`FromPgn.parseString`: its fast-packet reassembly and its field decoder), and prints each
// PGN it decodes.
//
//   node n2k_canboat_read.js PORT SECONDS [request]
//
// With `request`, it asks every device for its address claim once the channel is open (an ISO
// Request for PGN 60928 from the null address 254 to everyone, as a device starting up does).
//
// Prints JSON lines on standard output: {"event": "open"} once the channel is open, then for each
// PGN {"event": "pgn", "pgn": …, "src": …, "dst": …, "prio": …, "fields": {…}} (canboat's field
// identifiers and units: radians, kelvin), and {"event": "error", …} for what canboatjs cannot
// parse. Stops after SECONDS, or when standard input ends.

"use strict";

const fs = require("fs");
const { FromPgn } = require("@canboat/canboatjs");

const [port, seconds, request] = process.argv.slice(2);
if (!port || !seconds) {
  console.error("usage: node n2k_canboat_read.js PORT SECONDS");
  process.exit(2);
}

const parser = new FromPgn({ checkForInvalidFields: true });
parser.on("error", (data, error) => {
  console.log(JSON.stringify({ event: "error", data: String(data), error: String(error) }));
});

/** The candump line of an slcan extended data frame line (`T` id len data), or null. */
function candump(line) {
  const m = /^T([0-9A-Fa-f]{8})([0-8])([0-9A-Fa-f]*)$/.exec(line);
  if (!m) return null;
  const len = Number(m[2]);
  const data = m[3].slice(0, 2 * len);
  if (data.length !== 2 * len) return null;
  return `(0.000000) can0 ${m[1]}#${data}`;
}

const fd = fs.openSync(port, "r+");
const input = fs.createReadStream(null, { fd: fs.openSync(port, "r"), autoClose: true });
let buffer = "";
input.setEncoding("latin1");
input.on("data", (chunk) => {
  buffer += chunk;
  let cr;
  while ((cr = buffer.search(/[\r\n]/)) >= 0) {
    const line = buffer.slice(0, cr).replace(/^[\x07zZ]+/, "");
    buffer = buffer.slice(cr + 1);
    const text = candump(line);
    if (!text) continue;
    const pgn = parser.parseString(text);
    if (pgn) {
      console.log(
        JSON.stringify({
          event: "pgn",
          pgn: pgn.pgn,
          src: pgn.src,
          dst: pgn.dst,
          prio: pgn.prio,
          fields: pgn.fields,
        }),
      );
    }
  }
  if (buffer.length > 4096) buffer = "";
});
input.on("error", () => {});
// open the channel at 250 kbit/s, as a host opens an adapter
fs.writeSync(fd, "C\rS5\rO\r");
if (request === "request") {
  // priority 6, PGN 59904 to 255, from 254: PGN 60928 little-endian
  fs.writeSync(fd, "T18EAFFFE300EE00\r");
}
console.log(JSON.stringify({ event: "open" }));

function stop() {
  try {
    fs.writeSync(fd, "C\r");
  } catch (e) {
    // the adapter may be gone already
  }
  process.exit(0);
}
setTimeout(stop, Number(seconds) * 1000);
process.stdin.on("end", stop);
process.stdin.resume();
