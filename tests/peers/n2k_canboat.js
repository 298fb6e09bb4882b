// NMEA 2000 devices played by canboat's own JavaScript implementation (@canboat/canboatjs): each
// message of a JSON list is encoded by canboatjs (`pgnToCandump3`: its field encoder, its
// fast-packet framing and its CAN identifiers) and sent as slcan lines on a serial port or
// pseudo-terminal, as a host sends frames to an slcan adapter.
//
//   node n2k_canboat.js PORT SECONDS < messages.json
//
// messages.json: [{"pgn": 127250, "prio": 2, "src": 35, "dst": 255, "fields": {...}}, ...], the
// fields by canboat's identifiers in canboat's units (radians, kelvin). The whole list is sent every
// 300 ms for at most SECONDS, or until "stop" is read on standard input after the list. Each round
// also sends one broken fast packet (a GNSS position from address 99 with its third frame left
// out), which a receiver must drop and count. Reports JSON lines on standard output:
// {"event": "encoded", "pgn": …, "frames": ["09F11223#…", …]} for each message, then
// {"event": "round", "n": …} after each round.

"use strict";

const fs = require("fs");
const { pgnToCandump3 } = require("@canboat/canboatjs");

const [port, seconds] = process.argv.slice(2);
if (!port || !seconds) {
  console.error("usage: node n2k_canboat.js PORT SECONDS < messages.json");
  process.exit(2);
}

/** The slcan line of a candump line `(time) bus ID#DATA` (an extended data frame). */
function slcanLine(candump) {
  const frame = candump.trim().split(" ")[2];
  const [id, data] = frame.split("#");
  if (id.length > 8 || data.length % 2 !== 0 || data.length > 16) {
    throw new Error(`not a classic extended frame: ${candump}`);
  }
  return `T${id.padStart(8, "0").toUpperCase()}${data.length / 2}${data.toUpperCase()}\r`;
}

/** canboatjs's frames of one message, as slcan lines. */
function encode(message) {
  const lines = pgnToCandump3(JSON.parse(JSON.stringify(message)));
  if (!lines || lines.length === 0) {
    throw new Error(`canboatjs does not encode PGN ${message.pgn}`);
  }
  return lines.map(slcanLine);
}

let input = "";
let stopped = false;
process.stdin.setEncoding("utf8");
process.stdin.on("data", (chunk) => {
  input += chunk;
  if (/\nstop\s*$/.test(input)) stopped = true;
});
process.stdin.on("end", () => {
  stopped = true;
});

function start(messages) {
  const rounds = [];
  for (const m of messages) {
    const lines = encode(m);
    console.log(JSON.stringify({ event: "encoded", pgn: m.pgn, src: m.src, frames: lines.map((l) => l.trim()) }));
    rounds.push(...lines);
  }
  // the broken fast packet: a GNSS position from 99 without its third frame
  const gnss = messages.find((m) => m.pgn === 129029);
  const broken = encode({ ...gnss, src: 99 }).filter((_, i) => i !== 2);
  const fd = fs.openSync(port, "r+");
  // what the adapter answers (CR, Z) is read and left, so that its buffer never fills
  const answers = fs.createReadStream(null, { fd: fs.openSync(port, "r"), autoClose: true });
  answers.on("data", () => {});
  answers.on("error", () => {});
  // open the channel at 250 kbit/s, as a host opens an adapter
  fs.writeSync(fd, "C\rS5\rO\r");
  const deadline = Date.now() + Number(seconds) * 1000;
  let n = 0;
  const tick = () => {
    if (stopped || Date.now() > deadline) {
      fs.writeSync(fd, "C\r");
      fs.closeSync(fd);
      process.exit(0);
    }
    for (const line of rounds.concat(broken)) fs.writeSync(fd, line);
    n += 1;
    console.log(JSON.stringify({ event: "round", n }));
    setTimeout(tick, 300);
  };
  tick();
}

// the list is the first line of standard input
const waitForList = setInterval(() => {
  const nl = input.indexOf("\n");
  if (nl >= 0) {
    clearInterval(waitForList);
    start(JSON.parse(input.slice(0, nl)));
  } else if (stopped) {
    clearInterval(waitForList);
    console.error("no message list on standard input");
    process.exit(2);
  }
}, 10);
