// Watches a Foxglove WebSocket server with the official protocol client (@foxglove/ws-protocol
// over `ws`), subscribed to every channel, while a second connection sends what the protocol does
// not allow (text that is not JSON, an unknown binary opcode) every 200 ms for JUNK_SECONDS, then
// bytes that are no WebSocket frame at all. `foxglove.Log` messages (protobuf, as Foxglove's Log
// panel reads them) are decoded with protobufjs from the schema the channel advertises.
//
//   node foxglove_watch.js URL JUNK_SECONDS
//
// Prints "watching" once both connections are open; the watch lasts until standard input closes.
// A line "TOPIC N" on standard input makes the end wait (3 s at most) until N messages of TOPIC
// have arrived, as the last ones sent may still be on their way when the sender exits.
// Then it prints one JSON object: {"events": [{"t": ms, "event": "advertise"|"unadvertise",
// "topic": …}], "messages": {topic: [ms, …]}, "logs": [{level, name, message, file, line}],
// "junk": {"statuses": N, "sent": N, "garbage_at": ms, "closed_at": ms|null}}

"use strict";

const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const protobuf = require("protobufjs");
const descriptor = require("protobufjs/ext/descriptor");

const [url, junkText] = process.argv.slice(2);
const junkSeconds = Number(junkText);
if (!url || !(junkSeconds > 0)) {
  console.error("usage: node foxglove_watch.js URL JUNK_SECONDS");
  process.exit(2);
}
const started = Date.now();
const now = () => Date.now() - started;
// the watch starts once both connections are open ("watching" on a line of its own)
let watchFrom = null;
const out = {
  events: [],
  messages: {},
  logs: [],
  junk: { statuses: 0, sent: 0, garbage_at: null, closed_at: null },
};
const topics = new Map();
const subscriptions = new Map();
const logTypes = new Map();

// the subprotocols offered: exactly what the library's client offers (its README's
// `new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL])`), or the names in FOXGLOVE_OFFER
const offer = process.env.FOXGLOVE_OFFER
  ? process.env.FOXGLOVE_OFFER.split(",")
  : [FoxgloveClient.SUPPORTED_SUBPROTOCOL];
const ws = new WebSocket(url, offer);
const client = new FoxgloveClient({ ws });
client.on("advertise", (channels) => {
  for (const c of channels) {
    topics.set(c.id, c.topic);
    out.events.push({ t: now(), event: "advertise", topic: c.topic });
    const sub = client.subscribe(c.id);
    subscriptions.set(sub, c.topic);
    if (c.schemaName === "foxglove.Log" && c.encoding === "protobuf") {
      const set = descriptor.FileDescriptorSet.decode(Buffer.from(c.schema, "base64"));
      logTypes.set(sub, protobuf.Root.fromDescriptor(set).lookupType(c.schemaName));
    }
  }
});
client.on("unadvertise", (ids) => {
  for (const id of ids) {
    out.events.push({ t: now(), event: "unadvertise", topic: topics.get(id) });
  }
});
client.on("message", (m) => {
  const topic = subscriptions.get(m.subscriptionId);
  (out.messages[topic] = out.messages[topic] || []).push(now());
  const type = logTypes.get(m.subscriptionId);
  if (type) {
    const bytes = new Uint8Array(m.data.buffer, m.data.byteOffset, m.data.byteLength);
    const log = type.toObject(type.decode(bytes), { enums: String, defaults: true });
    out.logs.push({ level: log.level, name: log.name, message: log.message, file: log.file, line: log.line });
  }
});
client.on("error", (e) => {
  console.error(String(e));
  process.exit(1);
});

const junk = new WebSocket(url, ["foxglove.sdk.v1"]);
const open = { client: false, junk: false };
const opened = (which) => {
  open[which] = true;
  if (watchFrom !== null || !open.client || !open.junk) return;
  watchFrom = Date.now();
  console.log("watching");
  // the watch ends when whoever started it closes its standard input
  let input = "";
  process.stdin.on("data", (chunk) => {
    input += chunk;
  });
  process.stdin.on("end", () => {
    const [topic, count] = input.trim().split(/\s+/);
    const until = Date.now() + 3000;
    const finish = () => {
      const have = (out.messages[topic] || []).length;
      if (topic && have < Number(count) && Date.now() < until) return setTimeout(finish, 20);
      console.log(JSON.stringify(out));
      process.exit(0);
    };
    finish();
  });
  process.stdin.resume();
  setTimeout(() => {
    console.error("standard input still open after 60 s");
    process.exit(4);
  }, 60_000);
  const timer = setInterval(() => {
    if (junk.readyState !== WebSocket.OPEN) return clearInterval(timer);
    if (Date.now() - watchFrom < junkSeconds * 1000) {
      junk.send(out.junk.sent % 2 === 0 ? "{not json" : Buffer.from([0xff, 1, 2, 3]));
      out.junk.sent += 1;
    } else {
      // past the WebSocket layer: a line of text where a frame belongs
      junk._socket.write("GET / HTTP/1.1\r\n\r\n");
      out.junk.garbage_at = now();
      clearInterval(timer);
    }
  }, 200);
};
setTimeout(() => {
  if (watchFrom === null) {
    console.error("not both connections open within 20 s");
    process.exit(3);
  }
}, 20_000);
client.on("open", () => opened("client"));
junk.on("open", () => opened("junk"));
junk.on("message", (data, binary) => {
  if (!binary && JSON.parse(data.toString()).op === "status") out.junk.statuses += 1;
});
junk.on("error", () => {});
junk.on("close", () => {
  out.junk.closed_at = now();
});

