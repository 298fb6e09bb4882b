// Reads an MCAP file with the official TypeScript implementation (@mcap/core), through its
// indexed reader: the summary, the chunk indexes and the message indexes, as Foxglove reads files.
// zstd chunks are decompressed with fzstd.
//
//   node mcap_read.js FILE
//
// Prints one JSON object: {"chunks": N, "compression": [...], "messageCount": N,
// "channels": {topic: {"encoding": …, "schema": …, "schemaEncoding": …, "metadata": {…},
// "count": N, "first": <first message's JSON>}}}

"use strict";

const fs = require("fs");
const { McapIndexedReader } = require("@mcap/core");
const fzstd = require("fzstd");

async function main() {
  const file = process.argv[2];
  if (!file) {
    console.error("usage: node mcap_read.js FILE");
    process.exit(2);
  }
  const fd = fs.openSync(file, "r");
  const size = BigInt(fs.fstatSync(fd).size);
  const readable = {
    size: async () => size,
    read: async (offset, length) => {
      const buf = Buffer.alloc(Number(length));
      fs.readSync(fd, buf, 0, Number(length), Number(offset));
      return new Uint8Array(buf.buffer, buf.byteOffset, buf.length);
    },
  };
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: {
      zstd: (data, decompressedSize) => {
        const out = fzstd.decompress(data);
        if (BigInt(out.length) !== decompressedSize) {
          throw new Error(`zstd chunk: ${out.length} bytes, the chunk says ${decompressedSize}`);
        }
        return out;
      },
    },
  });
  const channels = {};
  for (const [id, c] of reader.channelsById) {
    const schema = reader.schemasById.get(c.schemaId);
    channels[c.topic] = {
      id,
      encoding: c.messageEncoding,
      schema: schema ? schema.name : "",
      schemaEncoding: schema ? schema.encoding : "",
      metadata: Object.fromEntries(c.metadata),
      count: 0,
      first: null,
    };
  }
  const byId = new Map(Object.values(channels).map((c) => [c.id, c]));
  const decoder = new TextDecoder();
  for await (const m of reader.readMessages({ validateCrcs: true })) {
    const c = byId.get(m.channelId);
    c.count += 1;
    if (c.first === null && c.encoding === "json") {
      c.first = JSON.parse(decoder.decode(m.data));
    }
  }
  const out = {
    chunks: reader.chunkIndexes.length,
    compression: [...new Set(reader.chunkIndexes.map((c) => c.compression))],
    messageCount: reader.statistics ? Number(reader.statistics.messageCount) : null,
    channels,
  };
  console.log(JSON.stringify(out));
}

main().catch((e) => {
  console.error(e && e.stack ? e.stack : String(e));
  process.exit(1);
});
