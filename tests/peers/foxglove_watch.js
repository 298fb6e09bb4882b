// Watches a Foxglove WebSocket server for SECONDS with the official protocol client
// (@foxglove/ws-protocol over `ws`), subscribed to every channel, while a second connection sends
// what the protocol does not allow (text that is not JSON, an unknown binary opcode) every 200 ms.
//
//   node foxglove_watch.js URL SECONDS
//
// Prints one JSON object: {"events": [{"t": ms, "event": "advertise"|"unadvertise", "topic": …}],
// "messages": {topic: [ms, …]}, "junk": {"statuses": N, "closed": bool, "sent": N}}

"use strict";

const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");

const [url, secondsText] = process.argv.slice(2);
const seconds = Number(secondsText);
if (!url || !(seconds > 0)) {
  console.error("usage: node foxglove_watch.js URL SECONDS");
  process.exit(2);
}
const started = Date.now();
const now = () => Date.now() - started;
const out = { events: [], messages: {}, junk: { statuses: 0, closed: false, sent: 0 } };
const topics = new Map();
const subscriptions = new Map();

const client = new FoxgloveClient({
  ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL, "foxglove.sdk.v1"]),
});
client.on("advertise", (channels) => {
  for (const c of channels) {
    topics.set(c.id, c.topic);
    out.events.push({ t: now(), event: "advertise", topic: c.topic });
    subscriptions.set(client.subscribe(c.id), c.topic);
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
});
client.on("error", (e) => {
  console.error(String(e));
  process.exit(1);
});

const junk = new WebSocket(url, ["foxglove.sdk.v1"]);
junk.on("open", () => {
  const timer = setInterval(() => {
    if (junk.readyState !== WebSocket.OPEN) return clearInterval(timer);
    junk.send(out.junk.sent % 2 === 0 ? "{not json" : Buffer.from([0xff, 1, 2, 3]));
    out.junk.sent += 1;
  }, 200);
});
junk.on("message", (data, binary) => {
  if (!binary && JSON.parse(data.toString()).op === "status") out.junk.statuses += 1;
});
junk.on("close", () => {
  out.junk.closed = true;
});

setTimeout(() => {
  console.log(JSON.stringify(out));
  process.exit(0);
}, seconds * 1000);
