// End-to-end check of Tessera's built-in web viewer in headless Chromium (playwright-core, the
// system's Chromium): opens the page a running `tessera ... --view PORT` serves, waits until it
// is connected and draws a map, a robot and a trajectory, optionally places a navigation goal
// through the UI, takes a screenshot and writes what the page saw (its window.tessera hooks)
// as JSON. Any console error or uncaught page error fails the check.
//
//   node viewer_e2e.mjs --url http://127.0.0.1:8765/ --screenshot OUT.png --out RESULT.json
//                       [--goal X,Y] [--initial-pose X,Y|robot] [--need LIST] [--linger-s S]
//                       [--timeout-s 60]
//
// --need: what the page must have drawn before the check goes on (comma-separated; default
// map,robot): map (tiles), robot (a pose and > 5 trajectory points), costmap (costmap tiles),
// local_plan (the dynamic window's arcs, seen at least once), cloud (3D map points), cameras
// (camera footprints). --linger-s: watch S seconds more before the screenshot.
//
// --initial-pose places a pose for the localiser with the "Initial pose" tool ("robot": where the
// page draws the robot now).
//
// Exit 0 on success; 1 with a message on stderr on failure or timeout (RESULT.json is still
// written, with "failure" set); 2 on bad arguments. CHROMIUM overrides /usr/bin/chromium.
import { chromium } from "playwright-core";
import { writeFileSync } from "node:fs";

const USAGE =
  "usage: node viewer_e2e.mjs --url URL --screenshot OUT.png --out RESULT.json [--goal X,Y] " +
  "[--initial-pose X,Y|robot] [--need map,robot,costmap,local_plan,cloud,cameras] [--timeout-s 60]";
const REQUIRED_LAYERS = ["map", "costmap", "cloud", "scan", "robot", "trajectory", "local_plan",
  "cameras"];
const NEEDS = ["map", "robot", "costmap", "local_plan", "cloud", "cameras"];

// Runs in the page (Playwright sends its source; it must be self-contained): what of `needs`
// the page's hooks (window.tessera) do not show yet, [] when all is there.
function pageLacks(needs) {
  const t = window.tessera;
  if (!t) return ["window.tessera is not defined (viewer.js did not run?)"];
  const checks = {
    map: [t.tiles > 0, "no map tiles"],
    robot: [t.robot !== null && t.trajectoryPoints > 5,
      `no robot pose or ${t.trajectoryPoints} trajectory points (want > 5)`],
    costmap: [t.costmapTiles > 0, "no costmap tiles"],
    local_plan: [!!t.scenes.local_plan && t.scenes.local_plan.peakLines > 0, "no dynamic window arcs"],
    cloud: [t.cloudPoints > 0, "no 3D map points"],
    cameras: [!!t.scenes.camera_footprints && t.scenes.camera_footprints.entities > 0, "no camera footprints"],
  };
  const lacks = t.connected ? [] : ["not connected"];
  for (const n of needs) if (!checks[n][0]) lacks.push(checks[n][1]);
  return lacks;
}
const STATUS_QUIET_MS = 1000; // after a goal, this long without an error status

function parseArgs(argv) {
  const opts = { url: null, screenshot: null, out: null, goal: null, initialPose: null, timeoutS: 60,
    need: ["map", "robot"], lingerS: 0 };
  for (let i = 0; i < argv.length; i++) {
    const key = argv[i];
    const value = argv[i + 1];
    const need = () => {
      if (value === undefined) usage(`${key} needs a value`);
      i++;
      return value;
    };
    switch (key) {
      case "--url": opts.url = need(); break;
      case "--screenshot": opts.screenshot = need(); break;
      case "--out": opts.out = need(); break;
      case "--goal": {
        const parts = need().split(",").map(Number);
        if (parts.length !== 2 || !parts.every(Number.isFinite)) usage(`--goal wants X,Y in metres, got '${value}'`);
        opts.goal = { x: parts[0], y: parts[1] };
        break;
      }
      case "--initial-pose": {
        const text = need();
        if (text === "robot") {
          opts.initialPose = "robot";
          break;
        }
        const parts = text.split(",").map(Number);
        if (parts.length !== 2 || !parts.every(Number.isFinite)) usage(`--initial-pose wants X,Y in metres or 'robot', got '${value}'`);
        opts.initialPose = { x: parts[0], y: parts[1] };
        break;
      }
      case "--need":
        opts.need = need().split(",").filter((n) => n.length > 0);
        for (const n of opts.need) if (!NEEDS.includes(n)) usage(`--need: unknown item '${n}' (known: ${NEEDS.join(", ")})`);
        break;
      case "--linger-s":
        opts.lingerS = Number(need());
        if (!(opts.lingerS >= 0)) usage(`--linger-s wants a number >= 0, got '${value}'`);
        break;
      case "--timeout-s":
        opts.timeoutS = Number(need());
        if (!(opts.timeoutS > 0)) usage(`--timeout-s wants a positive number, got '${value}'`);
        break;
      case "-h":
      case "--help":
        console.log(USAGE);
        process.exit(0);
        break;
      default: usage(`unknown argument '${key}'`);
    }
  }
  if (!opts.url || !opts.screenshot || !opts.out) usage("--url, --screenshot and --out are required");
  if ((opts.goal || opts.initialPose) && !opts.need.includes("map")) usage("--goal and --initial-pose need the map");
  if (opts.initialPose === "robot" && !opts.need.includes("robot")) usage("--initial-pose robot needs the robot");
  return opts;
}

function usage(message) {
  console.error(`viewer_e2e: ${message}\n${USAGE}`);
  process.exit(2);
}

class Failure extends Error {}

const opts = parseArgs(process.argv.slice(2));
const deadline = Date.now() + opts.timeoutS * 1000;
const remainingMs = () => Math.max(1, deadline - Date.now());

// A last resort if the browser itself hangs: never outlive the timeout by much.
const watchdog = setTimeout(() => {
  console.error(`viewer_e2e: FAILED: still running ${opts.timeoutS + 30} s after start`);
  process.exit(1);
}, (opts.timeoutS + 30) * 1000);
watchdog.unref();

const errors = []; // console errors and page errors, in order
const result = {
  ok: false,
  failure: null,
  url: opts.url,
  connected: false,
  tiles: 0,
  robot: null,
  robotWallMs: null,
  trajectoryPoints: 0,
  latenciesMs: [],
  messages: {},
  topics: [],
  goalSent: null,
  initialPoseSent: null,
  lastStatus: null,
  errors,
};

// The page's hooks as plain data (the functions dropped), with the page's clock at reading.
async function readState(page) {
  return page.evaluate(() => {
    const t = window.tessera;
    if (!t) return null;
    const { worldToScreen, screenToWorld, ...plain } = t;
    return { ...JSON.parse(JSON.stringify(plain)), nowMs: Date.now() };
  });
}

function copyState(state) {
  if (!state) return;
  for (const key of ["connected", "tiles", "costmapTiles", "cloudPoints", "cloudVoxel", "scenes",
    "robot", "trajectoryPoints", "latenciesMs", "messages", "topics", "lastStatus"]) {
    result[key] = state[key];
  }
}

// The goal and initial-pose tools work alike; what differs is the button and the counters.
const TOOLS = {
  goal: { button: "#goal-button", sent: "goalsSent", last: "lastGoal", name: "goal" },
  initial: { button: "#initial-pose-button", sent: "initialPosesSent", last: "lastInitialPose", name: "initial pose" },
};

// Places a pose with `tool` at `target`: {x, y} by a click (heading 0), or "robot": where the
// page draws the robot the moment the tool is active, dragged along its heading (a pose that is
// stale by the time it arrives would send a localiser astray on a moving robot).
async function placeGoal(page, target, tool = TOOLS.goal) {
  await page.click(tool.button);
  const robot = target === "robot" ? await page.evaluate(() => window.tessera.robot) : null;
  if (target === "robot" && !robot) throw new Failure("no robot drawn to place the pose at");
  const goal = robot ? { x: robot.x, y: robot.y } : target;
  // In placement mode the view stops following the robot, so the point stays put.
  const where = async () => page.evaluate(({ x, y }) => {
    const canvas = document.getElementById("map-canvas");
    const r = canvas.getBoundingClientRect();
    const p = window.tessera.worldToScreen(x, y);
    return { px: r.left + p.x, py: r.top + p.y, inside: p.x >= 1 && p.y >= 1 && p.x < r.width - 1 && p.y < r.height - 1 };
  }, goal);
  let at = await where();
  if (!at.inside) {
    // Off screen at this zoom: show the whole map (which leaves placement mode), then again.
    await page.keyboard.press("Escape");
    await page.click("#fit-button");
    await page.click(tool.button);
    at = await where();
    if (!at.inside) throw new Failure(`${tool.name} ${goal.x},${goal.y} is outside the map view even when fitted`);
  }
  const clickedAtMs = await page.evaluate(() => Date.now());
  await page.mouse.move(at.px, at.py);
  await page.mouse.down();
  if (robot) { // drag 40 px along the heading (screen y points down)
    await page.mouse.move(at.px + 40 * Math.cos(robot.theta), at.py - 40 * Math.sin(robot.theta), { steps: 4 });
  }
  await page.mouse.up();
  try {
    await page.waitForFunction((key) => window.tessera[key] >= 1, tool.sent, { timeout: Math.min(remainingMs(), 10000), polling: 50 });
  } catch {
    throw new Failure(`the ${tool.name} click sent nothing (window.tessera.${tool.sent} stayed 0)`);
  }
  await page.waitForTimeout(STATUS_QUIET_MS);
  const state = await readState(page);
  const refusals = (state.statuses || []).filter((s) => s.level >= 2 && s.t >= clickedAtMs);
  if (refusals.length) throw new Failure(`the server answered the ${tool.name} with an error: ${refusals.map((s) => s.message).join("; ")}`);
  const sent = state[tool.last];
  // The click lands on a whole pixel: allow a few pixels' worth of metres.
  const tolerance = 3 / state.view.scale + 1e-6;
  if (!sent || Math.hypot(sent.x - goal.x, sent.y - goal.y) > tolerance) {
    throw new Failure(`${tool.name} sent at ${JSON.stringify(sent)}, wanted ${goal.x},${goal.y} (±${tolerance.toFixed(3)} m)`);
  }
  if (robot && Math.abs(Math.atan2(Math.sin(sent.theta - robot.theta), Math.cos(sent.theta - robot.theta))) > 0.1) {
    throw new Failure(`${tool.name} sent with heading ${sent.theta.toFixed(3)}, the robot's is ${robot.theta.toFixed(3)} rad`);
  }
  result[tool === TOOLS.goal ? "goalSent" : "initialPoseSent"] = { x: sent.x, y: sent.y, theta: sent.theta };
  return state;
}

let browser = null;
let page = null;
try {
  browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || "/usr/bin/chromium",
    // No network beyond localhost here: nothing in the background may try to reach out.
    args: ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
      "--disable-background-networking", "--disable-quic", "--no-first-run",
      "--disable-component-update", "--disable-sync"],
    timeout: remainingMs(),
  });
  page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  page.on("console", (msg) => {
    if (msg.type() === "error") {
      const loc = msg.location();
      errors.push(`console error: ${msg.text()}${loc && loc.url ? ` (${loc.url}:${loc.lineNumber})` : ""}`);
    }
  });
  page.on("pageerror", (err) => errors.push(`page error: ${err.message}`));

  const response = await page.goto(opts.url, { waitUntil: "load", timeout: remainingMs() });
  if (!response || !response.ok()) {
    throw new Failure(`GET ${opts.url} answered ${response ? `HTTP ${response.status()}` : "nothing"}`);
  }

  // Polled from here, so that a timeout can say what was still missing.
  for (let lacks = await page.evaluate(pageLacks, opts.need); lacks.length > 0;
    lacks = await page.evaluate(pageLacks, opts.need)) {
    if (remainingMs() <= 1) {
      copyState(await readState(page).catch(() => null));
      throw new Failure(`timed out after ${opts.timeoutS} s waiting for the viewer: ${lacks.join(", ")}`);
    }
    await page.waitForTimeout(Math.min(100, remainingMs()));
  }

  for (const layer of REQUIRED_LAYERS) {
    const n = await page.locator(`input[type="checkbox"][data-layer="${layer}"]`).count();
    if (n !== 1) throw new Failure(`layer checkbox data-layer="${layer}": found ${n}, want 1`);
  }

  let state = await readState(page);
  copyState(state);
  result.robotWallMs = state.nowMs;

  if (opts.goal) {
    state = await placeGoal(page, opts.goal);
    result.lastStatus = state.lastStatus;
    result.messages = state.messages;
  }
  if (opts.initialPose) {
    const at = opts.initialPose;
    state = await placeGoal(page, at, TOOLS.initial);
    result.lastStatus = state.lastStatus;
    result.messages = state.messages;
  }

  if (opts.lingerS > 0) {
    await page.waitForTimeout(Math.min(opts.lingerS * 1000, remainingMs()));
    copyState(await readState(page));
  }
  await page.screenshot({ path: opts.screenshot, fullPage: true });
  if (errors.length) throw new Failure(`the page reported ${errors.length} error(s): ${errors[0]}`);
  result.ok = true;
} catch (err) {
  result.failure = err instanceof Failure ? err.message : `${err.name}: ${err.message}`;
  // A picture of the failure helps more than none.
  if (page) await page.screenshot({ path: opts.screenshot, fullPage: true }).catch(() => {});
} finally {
  if (browser) await browser.close().catch(() => {});
}

writeFileSync(opts.out, JSON.stringify(result, null, 2) + "\n");
if (result.ok) {
  const r = result.robot;
  console.log(`viewer_e2e: OK: ${result.tiles} tiles, ${result.costmapTiles} costmap tiles, ` +
    `${result.cloudPoints} cloud points` +
    (r ? `, robot at ${r.x.toFixed(2)},${r.y.toFixed(2)}, ${result.trajectoryPoints} trajectory points` : "") +
    (result.goalSent ? `, goal sent at ${result.goalSent.x.toFixed(2)},${result.goalSent.y.toFixed(2)}` : ""));
  process.exit(0);
}
console.error(`viewer_e2e: FAILED: ${result.failure}`);
for (const e of errors) console.error(`  ${e}`);
process.exit(1);
