// Connects to a running Tessera viewer the way Foxglove Studio does, with Foxglove's own client
// (@foxglove/ws-protocol over the `ws` package), subscribes to the channels a user would open,
// decodes what arrives and prints one JSON object describing it on stdout, for the C++ test to
// compare with the run's own outputs (tests/apps/view_e2e_test.cpp).
//
//   node foxglove_check.mjs ws://127.0.0.1:PORT [--timeout-s 30]
//
// Exit 0 with the JSON once every wanted channel delivered a message; 1 with a reason otherwise.
import wsProtocol from "@foxglove/ws-protocol"; // CommonJS: named exports via the default
const { FoxgloveClient } = wsProtocol;
import WebSocket from "ws";

const url = process.argv[2];
const ti = process.argv.indexOf("--timeout-s");
const timeoutS = ti > 0 ? Number(process.argv[ti + 1]) : 30;
if (!url || !url.startsWith("ws://") || !(timeoutS > 0)) {
  console.error("usage: node foxglove_check.mjs ws://HOST:PORT [--timeout-s S]");
  process.exit(2);
}

// Channels and what a Foxglove panel needs from each.
const wanted = {
  "foxglove.LaserScan": (m) => ({
    frame_id: m.frame_id,
    ranges: m.ranges.length,
    finite: m.ranges.filter((r) => Number.isFinite(r) && r > 0).length,
    start_angle: m.start_angle,
    end_angle: m.end_angle,
  }),
  "foxglove.Grid": (m) => ({
    frame_id: m.frame_id,
    column_count: m.column_count,
    cell_size: m.cell_size,
    cell_stride: m.cell_stride,
    rows: Buffer.from(m.data, "base64").length / m.row_stride,
    fields: m.fields.map((f) => f.name),
  }),
  "foxglove.PoseInFrame": (m) => ({
    frame_id: m.frame_id,
    stamp_ns: Number(BigInt(m.timestamp.sec) * 1000000000n + BigInt(m.timestamp.nsec)),
    x: m.pose.position.x,
    y: m.pose.position.y,
  }),
  "foxglove.FrameTransform": (m) => ({ parent: m.parent_frame_id, child: m.child_frame_id }),
  "tessera.Metrics": (m) => ({ actors: m.actors.map((a) => a.name), sim_s: m.sim_s }),
};
const topics = new Set(["scan", "map", "pose", "tf", "tessera/metrics"]);

const result = { server: null, channels: [], received: {}, decoded: {}, statuses: [] };
const decoder = new TextDecoder();
const client = new FoxgloveClient({
  ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
});
const bySubscription = new Map();

function done(code, reason) {
  if (reason) result.failure = reason;
  process.stdout.write(JSON.stringify(result, null, 2) + "\n");
  if (reason) console.error("foxglove_check: " + reason);
  client.close();
  process.exit(code);
}
const timer = setTimeout(() => {
  const missing = [...topics].filter((t) => !result.received[t]);
  done(1, `timed out after ${timeoutS} s; nothing yet on: ${missing.join(", ")}`);
}, timeoutS * 1000);

client.on("error", (e) => done(1, "connection error: " + (e?.message ?? e)));
client.on("serverInfo", (info) => {
  result.server = { name: info.name, capabilities: info.capabilities };
});
client.on("status", (s) => result.statuses.push(s));
client.on("advertise", (channels) => {
  for (const ch of channels) {
    result.channels.push({ topic: ch.topic, schemaName: ch.schemaName, encoding: ch.encoding });
    if (topics.has(ch.topic)) bySubscription.set(client.subscribe(ch.id), ch);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const ch = bySubscription.get(subscriptionId);
  if (!ch) return;
  let msg;
  try {
    msg = JSON.parse(decoder.decode(data));
  } catch (e) {
    done(1, `${ch.topic}: not JSON: ${e.message}`);
    return;
  }
  const decode = wanted[ch.schemaName];
  if (!decode) {
    done(1, `${ch.topic}: unexpected schema ${ch.schemaName}`);
    return;
  }
  result.received[ch.topic] = (result.received[ch.topic] ?? 0) + 1;
  result.decoded[ch.topic] = { ...decode(msg), log_time_ns: Number(timestamp) };
  if ([...topics].every((t) => result.received[t])) {
    clearTimeout(timer);
    done(0);
  }
});
