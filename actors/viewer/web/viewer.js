// Tessera's built-in live viewer (docs/viewer.md#live). One ES module, no build step, no
// external resources: it connects back to the server that served it with Foxglove's WebSocket
// protocol (foxglove.websocket.v1), subscribes to the channels it knows how to draw, and draws
// them on one canvas in the map frame (x right, y up). It can also publish navigation goals and
// initial poses (the protocol's clientPublish).
//
// Sections: constants and state · test hooks (window.tessera) · connection · channels and
// subscriptions · message decoding · map tiles · view and input · drawing · side panel.
//
// Drawing is on demand: every change asks for one frame (at most ~30 per second); an idle page
// never redraws.

// ---------------------------------------------------------------------------------------------
// Constants and state

const SUBPROTOCOL = "foxglove.websocket.v1";
const BACKOFF_MS = [1000, 2000, 4000, 5000]; // reconnect delays; the last one repeats
const LATENCIES_KEPT = 100;
const TRAJECTORY_CAP = 20000; // points per accumulated polyline
const TRAJECTORY_MIN_STEP_M = 0.01; // points closer than this to the previous one are dropped
const ROBOT_RADIUS_M = 0.25;
const MIN_FRAME_MS = 33; // redraw at most ~30 times a second
const CLICK_TOLERANCE_PX = 6; // a goal "drag" shorter than this is a plain click (heading 0)
const MIN_SCALE = 0.2; // px per m
const MAX_SCALE = 2000;
const LAYERS = ["map", "costmap", "cloud", "scan", "robot", "trajectory", "optimised",
  "ground_truth", "submaps", "loops", "path", "local_plan", "landmarks", "cameras"];
// The layer of each foxglove.SceneUpdate topic the page draws; any other scene topic (landmark
// and line maps: landmark_map, line_map, a simulator's true landmarks...) is drawn on
// "landmarks". submap_poses is read for the submaps layer (and the loop edges between them).
const SCENE_LAYERS = { local_plan: "local_plan", camera_footprints: "cameras" };
const sceneLayer = (topic) => SCENE_LAYERS[topic] || "landmarks";
// Channels fetched only while their layer is on (high rate or large messages).
const GATED_ROLES = { ground_truth: "ground_truth", cloud: "cloud" };
const CLOUD_MAX_PIXELS = 2048; // per side of the 3D map's top view

// An accumulated polyline: flat [x0, y0, x1, y1, ...], at most TRAJECTORY_CAP points.
class Polyline {
  xy = [];
  count = 0;

  add(x, y) {
    const n = this.xy.length;
    if (n >= 2 && Math.hypot(x - this.xy[n - 2], y - this.xy[n - 1]) < TRAJECTORY_MIN_STEP_M) return;
    this.xy.push(x, y);
    if (this.xy.length > 2 * TRAJECTORY_CAP) {
      // Drop the oldest tenth at once rather than one point per message.
      this.xy.splice(0, 2 * Math.ceil(TRAJECTORY_CAP / 10));
    }
    this.count = this.xy.length / 2;
  }

  clear() {
    this.xy = [];
    this.count = 0;
  }
}

// A grid drawn as tiles: the map (occupancy) or the costmap (costs in ROS costmap_2d values).
class TileLayer {
  constructor(kind) {
    this.kind = kind; // "map" | "cost": which colours
    this.tiles = new Map(); // "tx,ty" -> {tx, ty, canvas, known: world bounds of known cells or null}
    this.geometry = null; // {resolution, offsetX, offsetY, size}
  }

  clear() {
    this.tiles.clear();
    this.geometry = null;
  }
}

// What the page has received (cleared when the server starts a new session).
const data = {
  map: new TileLayer("map"),
  costmap: new TileLayer("cost"),
  cloud: null, // {canvas, x0, y0, width, height (world m), points, voxel, zLow, zHigh}
  scenes: new Map(), // topic -> Map(entity id -> {lines, texts}) in the map frame
  fitted: false, // zoomed to the map once already
  robot: null, // {x, y, theta, stampNs}
  trajectory: new Polyline(), // online estimate ("pose" or "localized_pose")
  optimised: new Polyline(), // "trajectory_final"
  groundTruth: new Polyline(), // "ground_truth"
  scans: new Map(), // topic -> latest foxglove.LaserScan
  transforms: new Map(), // "parent\0child" -> {x, y, theta}
  paths: new Map(), // topic -> flat [x0, y0, x1, y1, ...]
  submaps: new Map(), // id -> {x, y, theta}
  loops: new Map(), // "from-to" -> {from, to}
};

// The view: `scale` pixels per metre, (cx, cy) the world point at the canvas centre.
const view = { scale: 20, cx: 0, cy: 0, width: 1, height: 1, dpr: 1 };

const ui = {
  follow: true,
  mode: null, // null | "goal" | "initial_pose": the next click on the map places it
  placing: null, // {start: world, startPx, current: world, currentPx} while dragging a pose
  panning: null, // {x, y, moved} while dragging the view
  layers: Object.fromEntries(LAYERS.map((name) => [name, name !== "ground_truth"])),
};

// ---------------------------------------------------------------------------------------------
// Test hooks: the end-to-end test (tests/js/viewer_e2e.mjs) reads this object.

const hooks = {
  connected: false,
  topics: [], // every advertised topic
  subscribed: [], // topics this page subscribes to
  messages: {}, // topic -> messages received
  tiles: 0,
  costmapTiles: 0,
  cloudPoints: 0,
  cloudVoxel: null,
  scenes: {}, // topic -> {entities, lines}
  mapResolution: null,
  robot: null,
  trajectoryPoints: 0,
  latenciesMs: [], // per tiles message: receive time - the server's map receive time
  lastStatus: null, // the server's last status message {level, message}
  statuses: [], // the server's last status messages {level, message, t: Date.now()}
  goalsSent: 0,
  lastGoal: null,
  initialPosesSent: 0,
  lastInitialPose: null,
  layers: { ...ui.layers },
  view: { scale: view.scale, cx: view.cx, cy: view.cy },
  worldToScreen,
  screenToWorld,
};
window.tessera = hooks;

// ---------------------------------------------------------------------------------------------
// Connection

const conn = {
  ws: null,
  attempt: 0, // failed attempts since the last open connection (backoff index)
  retryTimer: null,
  sessionId: null,
  channels: new Map(), // server channel id -> {id, topic, encoding, schemaName, role}
  subscriptions: new Map(), // our subscription id -> channel
  subscriptionOf: new Map(), // server channel id -> our subscription id
  nextSubscriptionId: 1,
  clientChannels: new Map(), // topic -> our client channel id (advertised on this socket)
  nextClientChannelId: 1,
};

function connect() {
  clearTimeout(conn.retryTimer);
  setConnectionState("connecting");
  const scheme = location.protocol === "https:" ? "wss://" : "ws://";
  let ws;
  try {
    // The page's query string (e.g. ?token=...) goes on the WebSocket URL too.
    ws = new WebSocket(scheme + location.host + "/" + location.search, [SUBPROTOCOL]);
  } catch (err) {
    showStatus(2, "cannot open WebSocket: " + err.message, true);
    scheduleReconnect();
    return;
  }
  ws.binaryType = "arraybuffer";
  conn.ws = ws;
  ws.onopen = () => {
    conn.attempt = 0;
    setConnectionState("connected");
  };
  ws.onmessage = (event) => {
    try {
      if (typeof event.data === "string") onText(event.data);
      else onBinary(event.data);
    } catch (err) {
      // A malformed message must not stop the page, but it is a bug somewhere: say so (the
      // end-to-end test fails on console errors).
      console.error("tessera viewer: bad message:", err);
      showStatus(1, "bad message from server: " + err.message, true);
    }
  };
  ws.onclose = () => {
    if (conn.ws !== ws) return;
    conn.ws = null;
    forgetChannels();
    scheduleReconnect();
  };
  // An error is always followed by close, which handles it.
  ws.onerror = () => {};
}

function scheduleReconnect() {
  const delay = BACKOFF_MS[Math.min(conn.attempt, BACKOFF_MS.length - 1)];
  conn.attempt++;
  setConnectionState("disconnected", delay);
  conn.retryTimer = setTimeout(connect, delay);
}

// Channels, subscriptions and client channels belong to one socket.
function forgetChannels() {
  conn.channels.clear();
  conn.subscriptions.clear();
  conn.subscriptionOf.clear();
  conn.clientChannels.clear();
  hooks.topics = [];
  hooks.subscribed = [];
}

function isOpen() {
  return conn.ws !== null && conn.ws.readyState === WebSocket.OPEN;
}

function sendJson(obj) {
  if (isOpen()) conn.ws.send(JSON.stringify(obj));
}

function onText(text) {
  const msg = JSON.parse(text);
  switch (msg.op) {
    case "serverInfo":
      // Another session id means the server restarted: what we accumulated is stale.
      if (conn.sessionId !== null && msg.sessionId !== undefined && msg.sessionId !== conn.sessionId) {
        clearData();
      }
      if (msg.sessionId !== undefined) conn.sessionId = msg.sessionId;
      break;
    case "advertise":
      for (const ch of msg.channels || []) {
        conn.channels.set(ch.id, {
          id: ch.id, topic: String(ch.topic), encoding: ch.encoding || "",
          schemaName: ch.schemaName || "", role: null,
        });
      }
      updateSubscriptions();
      break;
    case "unadvertise":
      for (const id of msg.channelIds || []) {
        const subId = conn.subscriptionOf.get(id);
        if (subId !== undefined) {
          conn.subscriptions.delete(subId);
          conn.subscriptionOf.delete(id);
        }
        conn.channels.delete(id);
      }
      updateSubscriptions();
      break;
    case "status":
      showStatus(Number(msg.level) || 0, String(msg.message ?? ""), false);
      break;
    default:
      break; // other ops (removeStatus, serverTime, ...) are not used
  }
}

// ---------------------------------------------------------------------------------------------
// Channels and subscriptions

// Which of our decoders a channel feeds, or null to leave it alone.
// A costmap topic: "costmap", "local_costmap", "nav/costmap"...
function isCostmap(topic) {
  return /(^|[/_])costmap$/.test(topic);
}

function channelRole(ch) {
  if (ch.encoding === "tessera.tiles") {
    return isCostmap(ch.topic.replace(/\/tiles$/, "")) ? "cost_tiles" : "tiles";
  }
  switch (ch.schemaName) {
    case "foxglove.Grid": return isCostmap(ch.topic) ? "cost_grid" : "grid";
    case "foxglove.SceneUpdate": return ch.topic === "submap_poses" ? "submaps" : "scene";
    case "foxglove.PointCloud": return "cloud";
    case "foxglove.LaserScan": return "scan";
    case "foxglove.FrameTransform": return "tf";
    case "foxglove.PosesInFrame": return "path";
    case "foxglove.PoseInFrame":
      switch (ch.topic) {
        case "pose":
        case "localized_pose": return "pose";
        case "trajectory_final": return "optimised";
        case "ground_truth": return "ground_truth";
        default: return null; // odom, map_to_odom (other frames) and others are not drawn
      }
    default: break;
  }
  if (ch.encoding !== "json") return null;
  switch (ch.topic) {
    case "constraints":
    case "loop_constraints": return "constraints";
    case "nav_status": return "nav";
    case "tessera/metrics": return "metrics";
    default: return null;
  }
}

// The one channel a tile layer draws: a tiles channel if there is one (`preferred`/tiles
// first), else a full grid that has no tiles channel beside it.
function chooseGridChannel(channels, tilesRole, gridRole, preferred) {
  const topics = new Set(channels.map((c) => c.topic));
  const tiles = channels.filter((c) => c.role === tilesRole);
  const grids = channels.filter((c) => c.role === gridRole && !topics.has(c.topic + "/tiles"));
  return tiles.find((c) => c.topic === preferred + "/tiles") || tiles[0] ||
    grids.find((c) => c.topic === preferred) || grids[0] || null;
}

const gridTopics = { map: null, costmap: null }; // the channel each tile layer draws

function updateSubscriptions() {
  const channels = [...conn.channels.values()];
  for (const ch of channels) ch.role = channelRole(ch);
  const map = chooseGridChannel(channels, "tiles", "grid", "map");
  const costmap = chooseGridChannel(channels, "cost_tiles", "cost_grid", "costmap");
  for (const [name, ch] of [["map", map], ["costmap", costmap]]) {
    if ((ch ? ch.topic : null) !== gridTopics[name]) {
      if (gridTopics[name] !== null) clearTiles(data[name]);
      gridTopics[name] = ch ? ch.topic : null;
    }
  }
  // Ground truth comes at the simulator's odometry rate and the 3D map is large: they are only
  // fetched while their layer is on (so drawn from then on), which keeps a default page's load
  // on the stack low.
  const wanted = channels.filter((c) => {
    if (c.role === null) return false;
    if (c.role === "tiles" || c.role === "grid") return c === map;
    if (c.role === "cost_tiles" || c.role === "cost_grid") return c === costmap;
    const gate = GATED_ROLES[c.role];
    return gate === undefined || ui.layers[gate];
  });

  const subscribe = [];
  for (const ch of wanted) {
    if (conn.subscriptionOf.has(ch.id)) continue;
    const id = conn.nextSubscriptionId++;
    conn.subscriptions.set(id, ch);
    conn.subscriptionOf.set(ch.id, id);
    subscribe.push({ id, channelId: ch.id });
  }
  const unsubscribe = [];
  for (const [subId, ch] of conn.subscriptions) {
    if (!wanted.includes(ch)) {
      unsubscribe.push(subId);
      conn.subscriptions.delete(subId);
      conn.subscriptionOf.delete(ch.id);
    }
  }
  if (unsubscribe.length) sendJson({ op: "unsubscribe", subscriptionIds: unsubscribe });
  if (subscribe.length) sendJson({ op: "subscribe", subscriptions: subscribe });

  hooks.topics = channels.map((c) => c.topic);
  hooks.subscribed = [...conn.subscriptions.values()].map((c) => c.topic);
  updateInfo();
}

// The robot is the online SLAM estimate ("pose") when the server has one, else the localiser's.
function robotTopic() {
  for (const ch of conn.channels.values()) if (ch.topic === "pose" && ch.role === "pose") return "pose";
  return "localized_pose";
}

// Publishes `obj` as JSON on a client channel for `topic` (advertised on first use).
function publish(topic, schemaName, obj) {
  if (!isOpen()) {
    showStatus(2, `cannot send ${topic}: not connected`, true);
    return false;
  }
  let id = conn.clientChannels.get(topic);
  if (id === undefined) {
    id = conn.nextClientChannelId++;
    conn.clientChannels.set(topic, id);
    sendJson({ op: "advertise", channels: [{ id, topic, encoding: "json", schemaName }] });
  }
  const body = new TextEncoder().encode(JSON.stringify(obj));
  const frame = new Uint8Array(5 + body.length);
  frame[0] = 1; // client message data
  new DataView(frame.buffer).setUint32(1, id, true);
  frame.set(body, 5);
  conn.ws.send(frame);
  return true;
}

// ---------------------------------------------------------------------------------------------
// Message decoding

const utf8 = new TextDecoder();

function onBinary(buffer) {
  const dv = new DataView(buffer);
  if (buffer.byteLength < 13 || dv.getUint8(0) !== 1) return; // only message data (opcode 1)
  const ch = conn.subscriptions.get(dv.getUint32(1, true));
  if (!ch) return; // a message that crossed our unsubscribe
  hooks.messages[ch.topic] = (hooks.messages[ch.topic] || 0) + 1;
  const payload = new Uint8Array(buffer, 13);
  if (ch.role === "tiles") {
    decodeTiles(data.map, payload);
  } else if (ch.role === "cost_tiles") {
    decodeTiles(data.costmap, payload);
  } else {
    onJsonMessage(ch, JSON.parse(utf8.decode(payload)));
  }
  requestRedraw();
}

function num(v, fallback = 0) {
  const n = Number(v); // 64-bit integers arrive as strings
  return Number.isFinite(n) ? n : fallback;
}

function stampNs(t) {
  return t ? num(t.sec) * 1e9 + num(t.nsec) : 0;
}

function yawOf(q) {
  return q ? 2 * Math.atan2(num(q.z), num(q.w, 1)) : 0;
}

// foxglove.Pose -> {x, y, theta}
function planar(pose) {
  const p = (pose && pose.position) || {};
  return { x: num(p.x), y: num(p.y), theta: yawOf(pose && pose.orientation) };
}

function onJsonMessage(ch, msg) {
  switch (ch.role) {
    case "grid":
      decodeGrid(data.map, msg);
      break;
    case "cost_grid":
      decodeGrid(data.costmap, msg);
      break;
    case "scene":
      applyScene(ch.topic, msg);
      break;
    case "cloud":
      decodeCloud(msg);
      break;
    case "pose": {
      if (ch.topic !== robotTopic()) break;
      const p = planar(msg.pose);
      data.robot = { ...p, stampNs: stampNs(msg.timestamp) };
      data.trajectory.add(p.x, p.y);
      hooks.robot = { ...data.robot };
      hooks.trajectoryPoints = data.trajectory.count;
      break;
    }
    case "optimised": {
      const p = planar(msg.pose);
      data.optimised.add(p.x, p.y);
      break;
    }
    case "ground_truth": {
      const p = planar(msg.pose);
      data.groundTruth.add(p.x, p.y);
      break;
    }
    case "scan":
      data.scans.set(ch.topic, msg);
      break;
    case "tf": {
      const t = msg.translation || {};
      data.transforms.set(`${msg.parent_frame_id}\0${msg.child_frame_id}`,
        { x: num(t.x), y: num(t.y), theta: yawOf(msg.rotation) });
      break;
    }
    case "path": {
      const flat = [];
      for (const pose of msg.poses || []) {
        const p = planar(pose);
        flat.push(p.x, p.y);
      }
      data.paths.set(ch.topic, flat);
      break;
    }
    case "submaps":
      // One entity per submap (foxglove_json.cpp): its id in the metadata, its frame the arrow.
      if ((msg.deletions || []).some((d) => num(d.type) === 1)) data.submaps.clear();
      for (const e of msg.entities || []) {
        const id = (e.metadata || []).find((m) => m.key === "submap_id");
        const arrow = (e.arrows || [])[0];
        if (id && arrow) data.submaps.set(num(id.value), planar(arrow.pose));
      }
      break;
    case "constraints":
      // Only revisits (loop closures) are drawn; hand-overs just chain consecutive submaps.
      if (msg.kind === "revisit" || msg.kind === 1) {
        const from = num(msg.fromId), to = num(msg.toId);
        data.loops.set(`${from}-${to}`, { from, to });
      }
      break;
    case "nav":
      showNavStatus(msg);
      break;
    case "metrics":
      showMetrics(msg);
      break;
    default:
      break;
  }
}

function clearData() {
  clearTiles(data.map);
  clearTiles(data.costmap);
  data.cloud = null;
  data.scenes.clear();
  hooks.scenes = {};
  hooks.cloudPoints = 0;
  hooks.cloudVoxel = null;
  data.fitted = false;
  data.robot = null;
  data.trajectory.clear();
  data.optimised.clear();
  data.groundTruth.clear();
  for (const m of [data.scans, data.transforms, data.paths, data.submaps, data.loops]) m.clear();
  hooks.robot = null;
  hooks.trajectoryPoints = 0;
  hooks.latenciesMs = [];
  hooks.messages = {};
  requestRedraw();
}

// ---------------------------------------------------------------------------------------------
// Map tiles

const TILES_HEADER_BYTES = 44; // f64 res, f64 offset x, f64 offset y, u32 size, i64 stamp, i64 wall

// Colour of each cell value (as a byte: -1 = 255 unknown), RGBA. Free is near-white, occupied
// near-black, values between interpolate; unknown is mid grey.
const CELL_RGBA = (() => {
  const lut = new Uint8ClampedArray(256 * 4);
  const free = [250, 250, 250], occupied = [25, 28, 34], unknown = [128, 128, 128];
  for (let b = 0; b < 256; b++) {
    const v = b > 127 ? b - 256 : b; // as int8
    let rgb = unknown;
    if (v >= 0) {
      const t = Math.min(v, 100) / 100;
      rgb = free.map((f, i) => f + (occupied[i] - f) * t);
    }
    lut.set([...rgb, 255], b * 4);
  }
  return lut;
})();

// Costmap colours (ROS costmap_2d values as bytes): free and unknown transparent, costs from
// faint blue to purple, inscribed (99) cyan, lethal (100) magenta; drawn over the map.
const COST_RGBA = (() => {
  const lut = new Uint8ClampedArray(256 * 4);
  for (let v = 1; v <= 98; v++) {
    const t = v / 98;
    lut.set([60 + 120 * t, 90 - 60 * t, 255 - 55 * t, 30 + 90 * t], v * 4);
  }
  lut.set([0, 220, 230, 130], 99 * 4);
  lut.set([255, 0, 200, 150], 100 * 4);
  return lut;
})();

function clearTiles(layer) {
  layer.clear();
  tilesChanged(layer);
}

// `u8 reset | u32 header bytes | header | u32 n | n x (u32 part bytes | part)`; the header and
// part layouts are MapTiler's (actors/viewer/include/tessera/viewer/map_tiles.hpp).
function decodeTiles(layer, bytes) {
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const need = (at, n) => {
    if (at + n > bytes.byteLength) throw new Error(`tiles message truncated at byte ${at}`);
  };
  need(0, 5);
  const reset = dv.getUint8(0) !== 0;
  const headerBytes = dv.getUint32(1, true);
  if (headerBytes < TILES_HEADER_BYTES) throw new Error(`tiles header of ${headerBytes} bytes`);
  need(5, headerBytes + 4);
  const h = 5;
  const geometry = {
    resolution: dv.getFloat64(h, true),
    offsetX: dv.getFloat64(h + 8, true),
    offsetY: dv.getFloat64(h + 16, true),
    size: dv.getUint32(h + 24, true),
  };
  const wallNs = dv.getBigInt64(h + 36, true);
  if (!(geometry.resolution > 0) || geometry.size < 1 || geometry.size > 4096) {
    throw new Error(`tiles: bad geometry ${JSON.stringify(geometry)}`);
  }
  const g = layer.geometry;
  if (reset || !g || g.resolution !== geometry.resolution || g.offsetX !== geometry.offsetX ||
      g.offsetY !== geometry.offsetY || g.size !== geometry.size) {
    layer.tiles.clear();
  }
  layer.geometry = geometry;

  let at = 5 + headerBytes;
  const n = dv.getUint32(at, true);
  at += 4;
  const T = geometry.size;
  for (let i = 0; i < n; i++) {
    need(at, 4);
    const partBytes = dv.getUint32(at, true);
    at += 4;
    need(at, partBytes);
    if (partBytes !== 8 + T * T) throw new Error(`tile of ${partBytes} bytes, expected ${8 + T * T}`);
    const tx = dv.getInt32(at, true), ty = dv.getInt32(at + 4, true);
    putTile(layer, tx, ty, bytes.subarray(at + 8, at + partBytes));
    at += partBytes;
  }

  // The first tiles after (re)subscribing carry the map as it is, however old: that is its age,
  // not a delivery time, so only later updates count.
  if (wallNs > 0n && g && layer === data.map) {
    hooks.latenciesMs.push(Date.now() - Number(wallNs) / 1e6);
    if (hooks.latenciesMs.length > LATENCIES_KEPT) hooks.latenciesMs.shift();
  }
  tilesChanged(layer);
}

// Draws one tile's cells (row-major from its lowest-y row, as bytes) into its own canvas.
function putTile(layer, tx, ty, cells) {
  const T = layer.geometry.size;
  const lut = layer.kind === "cost" ? COST_RGBA : CELL_RGBA;
  const key = `${tx},${ty}`;
  let tile = layer.tiles.get(key);
  if (!tile) {
    const canvas = document.createElement("canvas");
    canvas.width = T;
    canvas.height = T;
    tile = { tx, ty, canvas, known: null };
    layer.tiles.set(key, tile);
  }
  const ctx = tile.canvas.getContext("2d");
  const image = ctx.createImageData(T, T);
  const px = image.data;
  let minX = T, minY = T, maxX = -1, maxY = -1;
  for (let i = 0; i < T * T; i++) {
    const b = cells[i];
    const o = b * 4, p = i * 4;
    px[p] = lut[o];
    px[p + 1] = lut[o + 1];
    px[p + 2] = lut[o + 2];
    px[p + 3] = lut[o + 3];
    if (b !== 255) { // known cell: grow the tile's known bounds (used to fit the view)
      const cx = i % T, cy = (i - cx) / T;
      if (cx < minX) minX = cx;
      if (cx > maxX) maxX = cx;
      if (cy < minY) minY = cy;
      if (cy > maxY) maxY = cy;
    }
  }
  // Image row 0 is the tile's lowest-y row: the world transform's y flip puts it at the bottom.
  ctx.putImageData(image, 0, 0);
  const { resolution: r, offsetX, offsetY } = layer.geometry;
  tile.known = maxX < 0 ? null : {
    x0: (tx * T + minX) * r + offsetX, y0: (ty * T + minY) * r + offsetY,
    x1: (tx * T + maxX + 1) * r + offsetX, y1: (ty * T + maxY + 1) * r + offsetY,
  };
}

function tilesChanged(layer) {
  if (layer === data.costmap) {
    hooks.costmapTiles = layer.tiles.size;
    return;
  }
  hooks.tiles = layer.tiles.size;
  hooks.mapResolution = layer.geometry ? layer.geometry.resolution : null;
  document.body.dataset.tiles = String(layer.tiles.size);
  fitOnce();
}

// Zooms to the map (or the 3D map's extent) the first time there is one.
function fitOnce() {
  if (!data.fitted && mapBounds()) {
    fitToMap();
    data.fitted = true;
  }
}

// A full foxglove.Grid (used only when the server offers no tiles channel): cut into tiles on
// the grid's own lattice so that one drawing path serves both.
function decodeGrid(layer, msg) {
  const T = 64;
  const cols = num(msg.column_count);
  const rowStride = num(msg.row_stride, cols);
  const cellStride = num(msg.cell_stride, 1);
  const resolution = num(msg.cell_size && msg.cell_size.x);
  const raw = Uint8Array.from(atob(msg.data || ""), (c) => c.charCodeAt(0));
  const field = (msg.fields || []).find((f) => f.name === "occupancy") || { offset: 0 };
  if (!(resolution > 0) || cols <= 0 || rowStride <= 0) throw new Error("grid: bad geometry");
  const rows = Math.floor(raw.length / rowStride);
  const origin = planar(msg.pose); // rotation of the grid is not drawn
  layer.tiles.clear();
  layer.geometry = { resolution, offsetX: origin.x, offsetY: origin.y, size: T };
  const cells = new Uint8Array(T * T);
  for (let ty = 0; ty * T < rows; ty++) {
    for (let tx = 0; tx * T < cols; tx++) {
      cells.fill(255);
      for (let cy = 0; cy < T && ty * T + cy < rows; cy++) {
        for (let cx = 0; cx < T && tx * T + cx < cols; cx++) {
          cells[cy * T + cx] = raw[(ty * T + cy) * rowStride + (tx * T + cx) * cellStride + num(field.offset)];
        }
      }
      putTile(layer, tx, ty, cells);
    }
  }
  tilesChanged(layer);
}

// World bounds of every known map cell, or of the 3D map without one, or null.
function mapBounds() {
  let b = null;
  for (const t of data.map.tiles.values()) {
    const k = t.known;
    if (!k) continue;
    if (!b) b = { ...k };
    else {
      b.x0 = Math.min(b.x0, k.x0); b.y0 = Math.min(b.y0, k.y0);
      b.x1 = Math.max(b.x1, k.x1); b.y1 = Math.max(b.y1, k.y1);
    }
  }
  const c = data.cloud;
  if (!b && c) b = { x0: c.x0, y0: c.y0, x1: c.x0 + c.width, y1: c.y0 + c.height };
  return b;
}

// ---------------------------------------------------------------------------------------------
// Scenes (foxglove.SceneUpdate) and the 3D map (foxglove.PointCloud)

function cssColor(c, fallback) {
  if (!c) return fallback;
  const u = (v) => Math.round(255 * Math.min(1, Math.max(0, num(v))));
  return `rgba(${u(c.r)}, ${u(c.g)}, ${u(c.b)}, ${Math.min(1, Math.max(0, num(c.a, 1)))})`;
}

// The entity's frame in the page's world (the map frame): through a known map -> frame
// transform, else taken as the map frame itself.
function frameInWorld(frame) {
  return data.transforms.get(`map\0${frame}`) || { x: 0, y: 0, theta: 0 };
}

// A SceneEntity's line and text primitives, transformed into the map frame once.
function sceneDrawable(e) {
  const frame = frameInWorld(String(e.frame_id || "map"));
  const place = (primitivePose, p) => {
    const pose = planar(primitivePose);
    const a = compose(pose, num(p.x), num(p.y));
    return compose(frame, a.x, a.y);
  };
  const lines = [];
  for (const l of e.lines || []) {
    const pts = (l.points || []).map((p) => place(l.pose, p));
    const type = num(l.type);
    const order = Array.isArray(l.indices) && l.indices.length ? l.indices.map((i) => num(i))
      : pts.map((_, i) => i);
    const xy = [];
    for (const i of order) if (pts[i]) xy.push(pts[i].x, pts[i].y);
    const thickness = num(l.thickness, 1);
    lines.push({
      type, xy, color: cssColor(l.color, "#ffffff"),
      widthPx: l.scale_invariant ? thickness : null, widthM: l.scale_invariant ? null : thickness,
    });
  }
  const spheres = (e.spheres || []).map((sp) => {
    const p = place(sp.pose, { x: 0, y: 0 });
    return { x: p.x, y: p.y, sizeM: num(sp.size && sp.size.x, 0.2), color: cssColor(sp.color, COLORS.landmark) };
  });
  const arrows = (e.arrows || []).map((a) => {
    const p = place(a.pose, { x: 0, y: 0 });
    const theta = planar(a.pose).theta + frame.theta;
    return { x: p.x, y: p.y, theta, lengthM: num(a.shaft_length) + num(a.head_length),
      color: cssColor(a.color, COLORS.text) };
  });
  const texts = (e.texts || []).map((t) => {
    const p = place(t.pose, { x: 0, y: 0 });
    return { x: p.x, y: p.y, text: String(t.text ?? ""), color: cssColor(t.color, COLORS.text),
      sizePx: t.scale_invariant !== false ? num(t.font_size, 12) : null, sizeM: num(t.font_size, 0.3) };
  });
  return { lines, spheres, arrows, texts };
}

function applyScene(topic, msg) {
  let scene = data.scenes.get(topic);
  if (!scene) {
    scene = new Map();
    data.scenes.set(topic, scene);
  }
  for (const d of msg.deletions || []) {
    if (num(d.type) === 1) scene.clear(); // ALL
    else scene.delete(String(d.id)); // MATCHING_ID
  }
  for (const e of msg.entities || []) scene.set(String(e.id), sceneDrawable(e));
  let lines = 0, spheres = 0;
  for (const e of scene.values()) {
    lines += e.lines.length;
    spheres += e.spheres.length;
  }
  const peakLines = Math.max(lines, hooks.scenes[topic] ? hooks.scenes[topic].peakLines : 0);
  hooks.scenes[topic] = { entities: scene.size, lines, spheres, peakLines };
}

function decodeBase64(text) {
  return Uint8Array.from(atob(text || ""), (c) => c.charCodeAt(0));
}

// The voxel edge of a cloud of voxel centres: the smallest step between distinct x values of a
// sample of points (points on a lattice), kept between 5 mm and 1 m.
function latticeStep(xs) {
  const sorted = Float64Array.from(xs).sort();
  let step = Infinity;
  for (let i = 1; i < sorted.length; i++) {
    const d = sorted[i] - sorted[i - 1];
    if (d > 1e-4 && d < step) step = d;
  }
  return Math.min(1, Math.max(0.005, Number.isFinite(step) ? step : 0.05));
}

// A foxglove.PointCloud (float32 x, y, z) as a top view: each pixel of a voxel-sized raster
// shows the highest point above it, coloured by height (low blue, high red). Which way is up:
// z in the robot's frames (map, odom, base_link, or a frame the map has a transform to); in any
// other frame −y, the camera optical convention (x right, y down, z forward) of a visual SLAM
// world that starts at its first camera (docs/viewer.md#live).
function decodeCloud(msg) {
  const bytes = decodeBase64(msg.data);
  const stride = num(msg.point_stride);
  const field = (name) => (msg.fields || []).find((f) => f.name === name);
  const fx = field("x"), fy = field("y"), fz = field("z");
  if (!fx || !fy || !fz || [fx, fy, fz].some((f) => num(f.type) !== 7) || stride < 12) {
    showStatus(2, "3D map: only float32 x, y, z point clouds are drawn", true);
    return;
  }
  const n = Math.floor(bytes.length / stride);
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const frameId = String(msg.frame_id || "map");
  const zUp = ["map", "odom", "base_link"].includes(frameId) || data.transforms.has(`map\0${frameId}`);
  const origin = planar(msg.pose);
  const frame = frameInWorld(frameId);
  const xs = new Float64Array(n), ys = new Float64Array(n), zs = new Float64Array(n);
  let m = 0;
  for (let i = 0; i < n; i++) {
    const at = i * stride;
    const x = dv.getFloat32(at + num(fx.offset), true), y = dv.getFloat32(at + num(fy.offset), true);
    const z = dv.getFloat32(at + num(fz.offset), true);
    if (!Number.isFinite(x) || !Number.isFinite(y) || !Number.isFinite(z)) continue;
    if (zUp) {
      const a = compose(origin, x, y), w = compose(frame, a.x, a.y);
      xs[m] = w.x;
      ys[m] = w.y;
      zs[m] = z + num(msg.pose && msg.pose.position && msg.pose.position.z);
    } else { // x right, z forward, up = −y: a right-handed top view
      xs[m] = x;
      ys[m] = z;
      zs[m] = -y;
    }
    m++;
  }
  hooks.cloudPoints = m;
  if (m === 0) {
    data.cloud = null;
    return;
  }
  let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
  for (let i = 0; i < m; i++) {
    x0 = Math.min(x0, xs[i]); x1 = Math.max(x1, xs[i]);
    y0 = Math.min(y0, ys[i]); y1 = Math.max(y1, ys[i]);
  }
  const sample = Math.max(1, Math.floor(m / 4096));
  const sx = [], sz = [];
  for (let i = 0; i < m; i += sample) {
    sx.push(xs[i]);
    sz.push(zs[i]);
  }
  const voxel = Math.max(latticeStep(sx), (x1 - x0) / CLOUD_MAX_PIXELS, (y1 - y0) / CLOUD_MAX_PIXELS);
  sz.sort((a, b) => a - b);
  const zLow = sz[Math.floor(0.02 * (sz.length - 1))], zHigh = sz[Math.floor(0.98 * (sz.length - 1))];
  // Voxel centres: the raster's cells are centred on them.
  x0 -= voxel / 2;
  y0 -= voxel / 2;
  const W = Math.max(1, Math.floor((x1 + voxel / 2 - x0) / voxel) + 1);
  const H = Math.max(1, Math.floor((y1 + voxel / 2 - y0) / voxel) + 1);
  const top = new Float32Array(W * H).fill(-Infinity);
  for (let i = 0; i < m; i++) {
    const cx = Math.min(W - 1, Math.floor((xs[i] - x0) / voxel));
    const cy = Math.min(H - 1, Math.floor((ys[i] - y0) / voxel));
    const k = cy * W + cx;
    if (zs[i] > top[k]) top[k] = zs[i];
  }
  const canvas = document.createElement("canvas");
  canvas.width = W;
  canvas.height = H;
  const c2d = canvas.getContext("2d");
  const image = c2d.createImageData(W, H);
  const px = image.data;
  const span = zHigh > zLow ? zHigh - zLow : 1;
  for (let k = 0; k < W * H; k++) {
    if (top[k] === -Infinity) continue;
    const t = Math.min(1, Math.max(0, (top[k] - zLow) / span));
    // Blue -> cyan -> yellow -> red.
    const r = t < 0.5 ? 40 + 2 * t * 200 : 240;
    const g = t < 0.5 ? 120 + 2 * t * 110 : 230 - (t - 0.5) * 2 * 180;
    const b = t < 0.5 ? 230 - 2 * t * 150 : 80 - (t - 0.5) * 2 * 60;
    px.set([r, g, b, 235], 4 * k); // image row 0 = lowest y, like the tiles
  }
  c2d.putImageData(image, 0, 0);
  data.cloud = { canvas, x0, y0, width: W * voxel, height: H * voxel, points: m, voxel, zLow, zHigh };
  hooks.cloudVoxel = voxel;
  fitOnce();
}

// ---------------------------------------------------------------------------------------------
// View and input

const canvas = document.getElementById("map-canvas");
const ctx = canvas.getContext("2d");

function worldToScreen(x, y) {
  return { x: view.width / 2 + (x - view.cx) * view.scale, y: view.height / 2 - (y - view.cy) * view.scale };
}

function screenToWorld(px, py) {
  return { x: view.cx + (px - view.width / 2) / view.scale, y: view.cy - (py - view.height / 2) / view.scale };
}

function clampScale(s) {
  return Math.min(MAX_SCALE, Math.max(MIN_SCALE, s));
}

function fitToMap() {
  const b = mapBounds();
  if (!b) return;
  measureCanvas();
  const w = Math.max(b.x1 - b.x0, 1), h = Math.max(b.y1 - b.y0, 1);
  view.scale = clampScale(0.92 * Math.min(view.width / w, view.height / h));
  view.cx = (b.x0 + b.x1) / 2;
  view.cy = (b.y0 + b.y1) / 2;
  syncView();
  requestRedraw();
}

// With "Follow robot" on, the view is centred on the robot, except while a goal or initial
// pose is being placed: the map must not slide under the cursor then.
function applyFollow() {
  if (ui.follow && data.robot && ui.mode === null) {
    view.cx = data.robot.x;
    view.cy = data.robot.y;
  }
}

function syncView() {
  applyFollow();
  hooks.view = { scale: view.scale, cx: view.cx, cy: view.cy };
}

function measureCanvas() {
  view.width = Math.max(1, canvas.clientWidth);
  view.height = Math.max(1, canvas.clientHeight);
  view.dpr = window.devicePixelRatio || 1;
}

function eventPoint(event) {
  const r = canvas.getBoundingClientRect();
  return { x: event.clientX - r.left, y: event.clientY - r.top };
}

function setFollow(on) {
  ui.follow = on;
  followBox.checked = on;
  syncView();
  requestRedraw();
}

canvas.addEventListener("pointerdown", (event) => {
  if (event.button !== 0) return;
  const p = eventPoint(event);
  canvas.setPointerCapture(event.pointerId);
  if (ui.mode) {
    const w = screenToWorld(p.x, p.y);
    ui.placing = { start: w, startPx: p, current: w, currentPx: p };
  } else {
    ui.panning = { x: p.x, y: p.y, moved: false };
    canvas.classList.add("dragging");
  }
  requestRedraw();
});

canvas.addEventListener("pointermove", (event) => {
  const p = eventPoint(event);
  if (ui.placing) {
    ui.placing.current = screenToWorld(p.x, p.y);
    ui.placing.currentPx = p;
    requestRedraw();
  } else if (ui.panning) {
    const dx = p.x - ui.panning.x, dy = p.y - ui.panning.y;
    if (!ui.panning.moved && Math.hypot(dx, dy) < 3) return; // a click, not a drag (yet)
    ui.panning.moved = true;
    if (ui.follow) setFollow(false); // panning away from the robot ends following
    view.cx -= dx / view.scale;
    view.cy += dy / view.scale;
    ui.panning.x = p.x;
    ui.panning.y = p.y;
    syncView();
    requestRedraw();
  }
});

function endPointer(event, cancelled) {
  if (ui.placing) {
    const pl = ui.placing;
    ui.placing = null;
    if (!cancelled) {
      const p = eventPoint(event);
      const end = screenToWorld(p.x, p.y);
      const dragged = Math.hypot(p.x - pl.startPx.x, p.y - pl.startPx.y) >= CLICK_TOLERANCE_PX;
      const theta = dragged ? Math.atan2(end.y - pl.start.y, end.x - pl.start.x) : 0;
      sendPose(ui.mode, { x: pl.start.x, y: pl.start.y, theta });
    }
    setMode(null);
  }
  if (ui.panning) {
    ui.panning = null;
    canvas.classList.remove("dragging");
  }
  requestRedraw();
}
canvas.addEventListener("pointerup", (event) => endPointer(event, false));
canvas.addEventListener("pointercancel", (event) => endPointer(event, true));

canvas.addEventListener("wheel", (event) => {
  event.preventDefault();
  // Pixel, line and page deltas: bring lines and pages to rough pixels.
  const unit = event.deltaMode === 1 ? 16 : event.deltaMode === 2 ? view.height : 1;
  const factor = Math.exp(-event.deltaY * unit * 0.0015);
  const scale = clampScale(view.scale * factor);
  if (ui.follow && data.robot && ui.mode === null) {
    view.scale = scale; // the robot stays at the centre
  } else {
    // Zoom about the cursor: the world point under it stays under it.
    const p = eventPoint(event);
    const w = screenToWorld(p.x, p.y);
    view.scale = scale;
    view.cx = w.x - (p.x - view.width / 2) / view.scale;
    view.cy = w.y + (p.y - view.height / 2) / view.scale;
  }
  syncView();
  requestRedraw();
}, { passive: false });

window.addEventListener("keydown", (event) => {
  if (event.key === "Escape" && ui.mode) {
    ui.placing = null;
    setMode(null);
    requestRedraw();
  }
});

window.addEventListener("resize", () => {
  syncView();
  requestRedraw();
});

const POSE_COMMANDS = {
  goal: { topic: "goal", label: "goal", button: "goal-button" },
  initial_pose: { topic: "initial_pose", label: "initial pose", button: "initial-pose-button" },
};

function setMode(mode) {
  ui.mode = mode;
  for (const [name, cmd] of Object.entries(POSE_COMMANDS)) {
    document.getElementById(cmd.button).classList.toggle("active", name === mode);
  }
  canvas.classList.toggle("placing", mode !== null);
  const hint = document.getElementById("hint");
  hint.classList.toggle("hidden", mode === null);
  if (mode) {
    hint.textContent = `Click to place the ${POSE_COMMANDS[mode].label}; drag to set its heading (Esc cancels)`;
  }
}

function sendPose(mode, pose) {
  const cmd = POSE_COMMANDS[mode];
  if (!cmd) return;
  const msg = { x: pose.x, y: pose.y, theta: pose.theta };
  if (!publish(cmd.topic, "tessera.PlanarPose", msg)) return;
  if (mode === "goal") {
    hooks.goalsSent++;
    hooks.lastGoal = msg;
  } else {
    hooks.initialPosesSent++;
    hooks.lastInitialPose = msg;
  }
  showStatus(0, `${cmd.label} sent: x ${msg.x.toFixed(2)} m, y ${msg.y.toFixed(2)} m, ` +
    `θ ${(msg.theta * 180 / Math.PI).toFixed(0)}°`, true);
}

for (const [name, cmd] of Object.entries(POSE_COMMANDS)) {
  document.getElementById(cmd.button).addEventListener("click", () => {
    setMode(ui.mode === name ? null : name); // a second click on the active button cancels
  });
}

const followBox = document.getElementById("follow");
followBox.addEventListener("change", () => setFollow(followBox.checked));

document.getElementById("fit-button").addEventListener("click", () => {
  if (ui.follow) setFollow(false); // otherwise the view jumps back to the robot
  fitToMap();
});

for (const box of document.querySelectorAll("input[data-layer]")) {
  const name = box.dataset.layer;
  ui.layers[name] = box.checked;
  box.addEventListener("change", () => {
    ui.layers[name] = box.checked;
    hooks.layers = { ...ui.layers };
    if (Object.values(GATED_ROLES).includes(name) && conn.ws) updateSubscriptions();
    requestRedraw();
  });
}
hooks.layers = { ...ui.layers };

// ---------------------------------------------------------------------------------------------
// Drawing

let framePending = false;
let lastFrame = 0;

function requestRedraw() {
  if (framePending) return;
  framePending = true;
  const wait = Math.max(0, lastFrame + MIN_FRAME_MS - performance.now());
  setTimeout(() => requestAnimationFrame(draw), wait);
}

const COLORS = {
  background: "#2b3036",
  scan: "#ff3b30",
  robot: "#1e88ff",
  trajectory: "#1e88ff",
  optimised: "#2fbf71",
  groundTruth: "rgba(255, 170, 0, 0.55)",
  path: "#00c8d7",
  submap: "#8e5cf7",
  loop: "#ff2fa0",
  landmark: "#e6a100",
  line: "#c0392b",
  goal: "#ff2fa0",
  initialPose: "#2fbf71",
  text: "#e4e7eb",
};

function draw() {
  framePending = false;
  lastFrame = performance.now();
  measureCanvas();
  const pw = Math.round(view.width * view.dpr), ph = Math.round(view.height * view.dpr);
  if (canvas.width !== pw || canvas.height !== ph) {
    canvas.width = pw;
    canvas.height = ph;
  }
  syncView();
  updateInfo();

  ctx.setTransform(view.dpr, 0, 0, view.dpr, 0, 0);
  ctx.fillStyle = COLORS.background;
  ctx.fillRect(0, 0, view.width, view.height);

  if (ui.layers.map) drawTiles(data.map);
  if (ui.layers.costmap) drawTiles(data.costmap);
  if (ui.layers.cloud) drawCloud();
  ctx.setTransform(view.dpr, 0, 0, view.dpr, 0, 0);
  ctx.lineJoin = "round";
  ctx.lineCap = "round";
  if (ui.layers.cameras) drawScene("camera_footprints");
  if (ui.layers.ground_truth) strokePolyline(data.groundTruth.xy, COLORS.groundTruth, 1.5);
  if (ui.layers.optimised) strokePolyline(data.optimised.xy, COLORS.optimised, 2);
  if (ui.layers.trajectory) strokePolyline(data.trajectory.xy, COLORS.trajectory, 1.5);
  if (ui.layers.path) for (const flat of data.paths.values()) strokePolyline(flat, COLORS.path, 2.5);
  if (ui.layers.local_plan) drawScene("local_plan");
  if (ui.layers.loops) drawLoops();
  if (ui.layers.submaps) drawSubmaps();
  for (const topic of data.scenes.keys()) {
    const layer = sceneLayer(topic);
    if (layer === "landmarks" && ui.layers.landmarks) drawScene(topic);
  }
  if (ui.layers.scan) drawScans();
  if (ui.layers.robot) drawRobot();
  if (hooks.lastGoal) drawPoseArrow(hooks.lastGoal, COLORS.goal, 0.6);
  if (ui.placing) drawPlacing();
  drawScaleBar();
  // Before the first map, when there will be one (a channel offers it) or nothing to see yet.
  if (!hooks.connected || (data.map.tiles.size === 0 && !data.cloud &&
      (gridTopics.map !== null || !data.robot))) {
    ctx.fillStyle = COLORS.text;
    ctx.font = "14px system-ui, sans-serif";
    ctx.textAlign = "center";
    ctx.fillText(hooks.connected ? "waiting for the map…" : "not connected", view.width / 2, view.height / 2);
    ctx.textAlign = "start";
  }
}

// World -> device pixels with y up: canvases of cells (tiles, the 3D map) drawn in world units.
function setWorldTransform() {
  const s = view.scale;
  ctx.setTransform(view.dpr * s, 0, 0, -view.dpr * s,
    view.dpr * (view.width / 2 - view.cx * s), view.dpr * (view.height / 2 + view.cy * s));
  ctx.imageSmoothingEnabled = false; // crisp cells when zoomed in
}

function drawTiles(layer) {
  const g = layer.geometry;
  if (!g) return;
  const s = view.scale;
  setWorldTransform();
  const side = g.size * g.resolution;
  // Half a pixel of overlap hides the hairline seams between neighbouring tiles.
  const overlap = 0.5 / s;
  const lo = screenToWorld(0, view.height), hi = screenToWorld(view.width, 0);
  for (const t of layer.tiles.values()) {
    const x0 = t.tx * side + g.offsetX, y0 = t.ty * side + g.offsetY;
    if (x0 > hi.x || y0 > hi.y || x0 + side < lo.x || y0 + side < lo.y) continue; // off screen
    ctx.drawImage(t.canvas, x0, y0, side + overlap, side + overlap);
  }
}

function drawCloud() {
  const c = data.cloud;
  if (!c) return;
  setWorldTransform();
  ctx.drawImage(c.canvas, c.x0, c.y0, c.width, c.height);
  ctx.setTransform(view.dpr, 0, 0, view.dpr, 0, 0);
}

// A scene topic's entities: lines (strip, loop, list) and labels, in the map frame.
function drawScene(topic) {
  const scene = data.scenes.get(topic);
  if (!scene) return;
  for (const e of scene.values()) {
    for (const l of e.lines) {
      if (l.xy.length < 4) continue;
      ctx.strokeStyle = l.color;
      ctx.lineWidth = l.widthPx !== null ? l.widthPx : Math.max(1, l.widthM * view.scale);
      ctx.beginPath();
      for (let i = 0; i < l.xy.length; i += 2) {
        const p = worldToScreen(l.xy[i], l.xy[i + 1]);
        if (i === 0 || (l.type === 2 && i % 4 === 0)) ctx.moveTo(p.x, p.y); // LINE_LIST: pairs
        else ctx.lineTo(p.x, p.y);
      }
      if (l.type === 1) ctx.closePath(); // LINE_LOOP
      ctx.stroke();
    }
    for (const sp of e.spheres) { // a disc, at least a few pixels across
      const p = worldToScreen(sp.x, sp.y);
      ctx.fillStyle = sp.color;
      ctx.beginPath();
      ctx.arc(p.x, p.y, Math.max(3, sp.sizeM * view.scale / 2), 0, 2 * Math.PI);
      ctx.fill();
    }
    for (const a of e.arrows) drawPoseArrow(a, a.color, a.lengthM);
    for (const t of e.texts) {
      const p = worldToScreen(t.x, t.y);
      const size = t.sizePx !== null ? t.sizePx : Math.max(8, t.sizeM * view.scale);
      ctx.font = `${Math.round(size)}px system-ui, sans-serif`;
      ctx.fillStyle = t.color;
      ctx.textAlign = "center";
      ctx.fillText(t.text, p.x, p.y);
      ctx.textAlign = "start";
    }
  }
}

function strokePolyline(flat, color, width) {
  if (flat.length < 4) return;
  ctx.strokeStyle = color;
  ctx.lineWidth = width;
  ctx.beginPath();
  for (let i = 0; i < flat.length; i += 2) {
    const p = worldToScreen(flat[i], flat[i + 1]);
    if (i === 0) ctx.moveTo(p.x, p.y);
    else ctx.lineTo(p.x, p.y);
  }
  ctx.stroke();
}

// pose ∘ (x, y): a point given in `pose`'s frame, in the world.
function compose(pose, x, y) {
  const c = Math.cos(pose.theta), s = Math.sin(pose.theta);
  return { x: pose.x + c * x - s * y, y: pose.y + s * x + c * y };
}

function drawScans() {
  const robot = data.robot;
  if (!robot) return;
  ctx.fillStyle = COLORS.scan;
  const dot = Math.max(1.5, Math.min(4, view.scale * 0.04));
  for (const scan of data.scans.values()) {
    // The laser's pose in the world: robot pose ∘ mount (base_link -> the scan's frame).
    const mount = scan.frame_id === "base_link" ? null
      : data.transforms.get(`base_link\0${scan.frame_id}`);
    const m = mount || { x: 0, y: 0, theta: 0 };
    const c = compose(robot, m.x, m.y);
    const laser = { x: c.x, y: c.y, theta: robot.theta + m.theta };
    const ranges = scan.ranges || [];
    const a0 = num(scan.start_angle), a1 = num(scan.end_angle);
    const step = ranges.length > 1 ? (a1 - a0) / (ranges.length - 1) : 0;
    for (let i = 0; i < ranges.length; i++) {
      const r = num(ranges[i]);
      if (!(r > 0)) continue; // 0: no return
      const a = a0 + i * step;
      const w = compose(laser, r * Math.cos(a), r * Math.sin(a));
      const p = worldToScreen(w.x, w.y);
      ctx.fillRect(p.x - dot / 2, p.y - dot / 2, dot, dot);
    }
  }
}

function drawRobot() {
  const r = data.robot;
  if (!r) return;
  const p = worldToScreen(r.x, r.y);
  const radius = Math.max(5, ROBOT_RADIUS_M * view.scale);
  ctx.beginPath();
  ctx.arc(p.x, p.y, radius, 0, 2 * Math.PI);
  ctx.fillStyle = "rgba(30, 136, 255, 0.35)";
  ctx.fill();
  ctx.lineWidth = 2;
  ctx.strokeStyle = COLORS.robot;
  ctx.stroke();
  // Heading: screen y points down, hence the minus.
  ctx.beginPath();
  ctx.moveTo(p.x, p.y);
  ctx.lineTo(p.x + Math.cos(r.theta) * radius * 1.4, p.y - Math.sin(r.theta) * radius * 1.4);
  ctx.strokeStyle = "#ffffff";
  ctx.stroke();
}

function drawSubmaps() {
  if (data.submaps.size === 0) return;
  const size = Math.max(6, Math.min(14, 0.3 * view.scale));
  const labels = data.submaps.size <= 200 || view.scale > 30; // avoid a wall of numbers
  ctx.font = "10px system-ui, sans-serif";
  ctx.lineWidth = 1.5;
  for (const [id, pose] of data.submaps) {
    const p = worldToScreen(pose.x, pose.y);
    const c = Math.cos(pose.theta), s = -Math.sin(pose.theta); // screen y down
    // A triangle pointing along the submap frame's x axis.
    ctx.beginPath();
    ctx.moveTo(p.x + c * size, p.y + s * size);
    ctx.lineTo(p.x - c * size * 0.5 - s * size * 0.5, p.y - s * size * 0.5 + c * size * 0.5);
    ctx.lineTo(p.x - c * size * 0.5 + s * size * 0.5, p.y - s * size * 0.5 - c * size * 0.5);
    ctx.closePath();
    ctx.strokeStyle = COLORS.submap;
    ctx.stroke();
    if (labels) {
      ctx.fillStyle = COLORS.submap;
      ctx.fillText(String(id), p.x + size * 0.7, p.y - size * 0.7);
    }
  }
}

function drawLoops() {
  ctx.strokeStyle = COLORS.loop;
  ctx.lineWidth = 1.5;
  ctx.setLineDash([5, 4]);
  ctx.beginPath();
  for (const { from, to } of data.loops.values()) {
    const a = data.submaps.get(from), b = data.submaps.get(to);
    if (!a || !b) continue; // drawn once both submaps' poses are known
    const pa = worldToScreen(a.x, a.y), pb = worldToScreen(b.x, b.y);
    ctx.moveTo(pa.x, pa.y);
    ctx.lineTo(pb.x, pb.y);
  }
  ctx.stroke();
  ctx.setLineDash([]);
}

// An arrow `lengthM` long from the pose along its heading, with a dot at the position.
function drawPoseArrow(pose, color, lengthM) {
  const p = worldToScreen(pose.x, pose.y);
  const len = Math.max(18, lengthM * view.scale);
  const c = Math.cos(pose.theta), s = -Math.sin(pose.theta);
  const tip = { x: p.x + c * len, y: p.y + s * len };
  ctx.strokeStyle = color;
  ctx.fillStyle = color;
  ctx.lineWidth = 2.5;
  ctx.beginPath();
  ctx.arc(p.x, p.y, 4, 0, 2 * Math.PI);
  ctx.fill();
  ctx.beginPath();
  ctx.moveTo(p.x, p.y);
  ctx.lineTo(tip.x, tip.y);
  ctx.moveTo(tip.x - c * 8 - s * 5, tip.y - s * 8 + c * 5);
  ctx.lineTo(tip.x, tip.y);
  ctx.lineTo(tip.x - c * 8 + s * 5, tip.y - s * 8 - c * 5);
  ctx.stroke();
}

function drawPlacing() {
  const pl = ui.placing;
  const dragged = Math.hypot(pl.currentPx.x - pl.startPx.x, pl.currentPx.y - pl.startPx.y) >= CLICK_TOLERANCE_PX;
  const theta = dragged ? Math.atan2(pl.current.y - pl.start.y, pl.current.x - pl.start.x) : 0;
  drawPoseArrow({ x: pl.start.x, y: pl.start.y, theta },
    ui.mode === "goal" ? COLORS.goal : COLORS.initialPose, 0.6);
}

// A 1-2-5 scale bar of about 100 px in the lower left corner.
function drawScaleBar() {
  const target = 100 / view.scale;
  const pow = Math.pow(10, Math.floor(Math.log10(target)));
  const metres = [1, 2, 5, 10].map((m) => m * pow).find((m) => m >= target * 0.7) || pow * 10;
  const px = metres * view.scale;
  const x = 14, y = view.height - 14;
  ctx.strokeStyle = COLORS.text;
  ctx.lineWidth = 2;
  ctx.beginPath();
  ctx.moveTo(x, y - 5);
  ctx.lineTo(x, y);
  ctx.lineTo(x + px, y);
  ctx.lineTo(x + px, y - 5);
  ctx.stroke();
  ctx.fillStyle = COLORS.text;
  ctx.font = "11px system-ui, sans-serif";
  ctx.fillText(metres >= 1 ? `${metres} m` : `${Math.round(metres * 100)} cm`, x + 4, y - 6);
}

// ---------------------------------------------------------------------------------------------
// Side panel

function setConnectionState(state, retryMs) {
  const el = document.getElementById("connection");
  el.className = "connection state-" + state;
  el.textContent = state === "connected" ? "connected"
    : state === "connecting" ? "connecting…"
      : `disconnected · retry in ${Math.round(retryMs / 1000)} s`;
  hooks.connected = state === "connected";
  document.body.dataset.connected = String(hooks.connected);
  updateInfo();
  requestRedraw();
}

// `local`: the page's own message (not the server's), shown but not recorded as lastStatus.
function showStatus(level, message, local) {
  const el = document.getElementById("status-line");
  el.className = "status-line level-" + level;
  el.textContent = (local ? "" : "server: ") + message;
  if (!local) {
    hooks.lastStatus = { level, message };
    hooks.statuses.push({ level, message, t: Date.now() });
    if (hooks.statuses.length > 20) hooks.statuses.shift();
  }
}

function showNavStatus(msg) {
  const parts = [`goal ${msg.goalId ?? "—"}: ${msg.state ?? "?"}`];
  if (msg.distanceRemaining !== undefined && msg.state !== "idle") {
    parts.push(`${num(msg.distanceRemaining).toFixed(1)} m to go`);
  }
  if (msg.reason) parts.push(String(msg.reason));
  document.getElementById("nav-status").textContent = "navigation: " + parts.join(" · ");
}

function fmt(v, digits = 0) {
  return v === undefined || v === null ? "—" : num(v).toFixed(digits);
}

function showMetrics(msg) {
  document.getElementById("metrics-section").classList.remove("hidden");
  const wall = num(msg.wall_s), sim = num(msg.sim_s);
  document.getElementById("metrics-clock").textContent =
    `wall ${wall.toFixed(1)} s · sim ${sim.toFixed(1)} s` + (wall > 0 ? ` · ×${(sim / wall).toFixed(2)}` : "");
  const progress = document.getElementById("metrics-progress");
  const hasProgress = msg.progress !== null && msg.progress !== undefined;
  progress.classList.toggle("hidden", !hasProgress);
  if (hasProgress) progress.value = Math.min(1, Math.max(0, num(msg.progress)));

  const body = document.querySelector("#metrics-table tbody");
  const rows = [];
  for (const a of msg.actors || []) {
    const tr = document.createElement("tr");
    const cells = [String(a.name ?? ""), fmt(a.in_per_s, 1), fmt(a.drops),
      `${fmt(a.queue_depth)} / ${fmt(a.max_queue_depth)}`, `${fmt(a.busy_pct, 1)} %`];
    cells.forEach((text, i) => {
      const td = document.createElement("td");
      td.textContent = text;
      if (i === 0) td.title = text;
      if (i === 2 && num(a.drops) > 0) td.className = "bad";
      tr.appendChild(td);
    });
    rows.push(tr);
  }
  body.replaceChildren(...rows);
}

function median(values) {
  if (values.length === 0) return null;
  const s = [...values].sort((a, b) => a - b);
  return s[Math.floor(s.length / 2)];
}

function updateInfo() {
  const lines = [`${hooks.topics.length} topics, ${hooks.subscribed.length} subscribed`];
  if (hooks.tiles > 0) {
    lines.push(`map: ${hooks.tiles} tiles, ${+hooks.mapResolution.toPrecision(4)} m/cell`);
    const m = median(hooks.latenciesMs);
    if (m !== null) lines.push(`map latency: ${m.toFixed(0)} ms (median)`);
  }
  if (hooks.costmapTiles > 0) lines.push(`costmap: ${hooks.costmapTiles} tiles`);
  const c = data.cloud;
  if (c) {
    lines.push(`3D map: ${c.points} points, ${(c.voxel * 100).toFixed(1)} cm, ` +
      `height ${c.zLow.toFixed(2)}…${c.zHigh.toFixed(2)} m`);
  }
  const r = hooks.robot;
  if (r) {
    lines.push(`robot: ${r.x.toFixed(2)}, ${r.y.toFixed(2)} m, ${(r.theta * 180 / Math.PI).toFixed(0)}°`);
  }
  document.getElementById("info").textContent = lines.join("\n");
}

// ---------------------------------------------------------------------------------------------

measureCanvas();
syncView();
connect();
requestRedraw();
