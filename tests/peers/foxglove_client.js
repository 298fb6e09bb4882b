// A Foxglove WebSocket client built on the official protocol library (@foxglove/ws-protocol, over
// the `ws` package), as Foxglove and Lichtblick connect to a live server.
//
//   node foxglove_client.js URL COUNT TOPIC...
//
// Lists the advertised channels, subscribes to each TOPIC, and collects COUNT messages of each
// (JSON channels decoded, others by size). Then, when the server takes client publishing, it
// advertises `cmd.mission` and sends one (which the server should refuse), and `cmd.course` with a
// course (which it should take). Offers the subprotocols FOXGLOVE_OFFER names (comma-separated),
// else exactly what the library offers. Prints one JSON object and exits:
// {"serverInfo": …, "protocol": the subprotocol chosen,
//  "channels": [{topic, encoding, schemaName, schemaEncoding, schema}],
//  "messages": {topic: [{"timestamp": "ns", "data": …}]}, "statuses": [{level, message}]}

"use strict";

const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");

const [url, countText, ...topics] = process.argv.slice(2);
const count = Number(countText);
if (!url || !(count > 0) || topics.length === 0) {
  console.error("usage: node foxglove_client.js URL COUNT TOPIC...");
  process.exit(2);
}

const out = { serverInfo: null, channels: [], messages: {}, statuses: [] };
const subscriptions = new Map();
const decoder = new TextDecoder();
let published = false;
// the subprotocols offered: exactly what the library's client offers (its README's
// `new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL])`), or the names in FOXGLOVE_OFFER
const offer = process.env.FOXGLOVE_OFFER
  ? process.env.FOXGLOVE_OFFER.split(",")
  : [FoxgloveClient.SUPPORTED_SUBPROTOCOL];
const ws = new WebSocket(url, offer);
const client = new FoxgloveClient({ ws });

function done() {
  return topics.every((t) => (out.messages[t] || []).length >= count);
}

function finish(code) {
  console.log(JSON.stringify(out));
  client.close();
  process.exit(code);
}

function publishCommands() {
  if (published || !out.serverInfo || !out.serverInfo.capabilities.includes("clientPublish")) {
    return;
  }
  published = true;
  const encoder = new TextEncoder();
  const mission = client.advertise({ topic: "cmd.mission", encoding: "json", schemaName: "" });
  client.sendMessage(mission, encoder.encode(JSON.stringify({ action: "start" })));
  const course = client.advertise({ topic: "cmd.course", encoding: "json", schemaName: "" });
  client.sendMessage(
    course,
    encoder.encode(JSON.stringify({ heading: 123.0, depth: 4.0, speed: 1.25 })),
  );
}

client.on("serverInfo", (info) => {
  out.serverInfo = info;
  // the subprotocol the server chose
  out.protocol = ws.protocol;
});
client.on("status", (s) => out.statuses.push({ level: s.level, message: s.message }));
client.on("advertise", (channels) => {
  for (const c of channels) {
    out.channels.push({
      topic: c.topic,
      encoding: c.encoding,
      schemaName: c.schemaName,
      schemaEncoding: c.schemaEncoding,
      schema: c.schema,
    });
    if (topics.includes(c.topic) && ![...subscriptions.values()].includes(c.topic)) {
      subscriptions.set(client.subscribe(c.id), c.topic);
    }
  }
});
client.on("message", (m) => {
  const topic = subscriptions.get(m.subscriptionId);
  const list = (out.messages[topic] = out.messages[topic] || []);
  if (list.length >= count) return;
  const bytes = new Uint8Array(m.data.buffer, m.data.byteOffset, m.data.byteLength);
  const channel = out.channels.find((c) => c.topic === topic);
  const data = channel.encoding === "json" ? JSON.parse(decoder.decode(bytes)) : bytes.length;
  list.push({ timestamp: m.timestamp.toString(), data });
  if (done()) {
    publishCommands();
    // the server's answers to what was published come within a moment
    setTimeout(() => finish(0), 1000);
  }
});
client.on("error", (e) => {
  console.error(String(e));
  finish(1);
});
setTimeout(() => finish(done() ? 0 : 1), 30000);
