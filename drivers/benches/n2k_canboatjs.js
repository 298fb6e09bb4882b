// The NMEA 2000 decode rate of canboat's own JavaScript implementation, for `cargo bench -p
// seabus-drivers --bench n2k`: every candump line of FILE handed to canboatjs's parser
// (`FromPgn.parseString`: the line read, fast packets reassembled, fields decoded), best of RUNS.
//
//   node n2k_canboatjs.js FILE RUNS
//
// Prints one JSON line: {"frames": …, "pgns": …, "seconds": …} (the best run).

"use strict";

const fs = require("fs");
const { FromPgn } = require("@canboat/canboatjs");

const [file, runs] = process.argv.slice(2);
const lines = fs.readFileSync(file, "utf8").split("\n").filter((l) => l.length > 0);
let best = null;
for (let r = 0; r < Number(runs || 5); r++) {
  const parser = new FromPgn({});
  parser.on("error", () => {});
  let pgns = 0;
  const start = process.hrtime.bigint();
  for (const l of lines) {
    if (parser.parseString(l)) pgns += 1;
  }
  const seconds = Number(process.hrtime.bigint() - start) / 1e9;
  if (best === null || seconds < best.seconds) best = { frames: lines.length, pgns, seconds };
}
console.log(JSON.stringify(best));
