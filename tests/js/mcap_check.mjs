// Reads an MCAP file with the ecosystem's reader (@mcap/core): once through the summary and
// chunk indexes (McapIndexedReader, CRCs checked), once front to back (McapStreamReader), and
// prints one JSON object: per topic the schema, encoding and message count, the first message
// of each topic decoded, and whether both passes agree. Exit 1 on any read error.
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { decompress } from "fzstd";
import { open } from "node:fs/promises";
import { readFileSync } from "node:fs";

const file = process.argv[2];
if (!file) {
  console.error("usage: node mcap_check.mjs FILE.mcap");
  process.exit(2);
}
const decompressHandlers = {
  zstd: (data, size) => {
    const out = decompress(data, new Uint8Array(Number(size)));
    return out;
  },
};

const handle = await open(file, "r");
const readable = {
  size: async () => BigInt((await handle.stat()).size),
  read: async (offset, length) => {
    const buf = new Uint8Array(Number(length));
    await handle.read(buf, 0, Number(length), Number(offset));
    return buf;
  },
};
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
const topics = {};
for (const [, ch] of reader.channelsById) {
  const schema = ch.schemaId === 0 ? null : reader.schemasById.get(ch.schemaId);
  topics[ch.topic] = {
    schema: schema ? schema.name : "",
    schema_encoding: schema ? schema.encoding : "",
    message_encoding: ch.messageEncoding,
    metadata: Object.fromEntries(ch.metadata),
    indexed: 0,
    streamed: 0,
    first: null,
    last_time_ns: null,
  };
}
let previous = -1n;
let ordered = true;
const byId = (id) => topics[reader.channelsById.get(id).topic];
for await (const m of reader.readMessages()) {
  const t = byId(m.channelId);
  if (m.logTime < previous) ordered = false;
  previous = m.logTime;
  t.indexed += 1;
  if (t.first === null) t.first = JSON.parse(new TextDecoder().decode(m.data));
  t.last_time_ns = m.logTime.toString();
}

const stream = new McapStreamReader({ decompressHandlers, validateCrcs: true });
stream.append(readFileSync(file));
const channels = new Map();
for (let rec; (rec = stream.nextRecord()); ) {
  if (rec.type === "Channel") channels.set(rec.id, rec.topic);
  if (rec.type === "Message") topics[channels.get(rec.channelId)].streamed += 1;
}
const stats = reader.statistics;
console.log(
  JSON.stringify({
    ok: stream.done(),
    ordered,
    message_count: stats ? Number(stats.messageCount) : null,
    chunk_count: stats ? stats.chunkCount : null,
    library: reader.header.library,
    topics,
  }),
);
await handle.close();
