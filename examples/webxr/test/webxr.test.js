// The WebXR example in Debian's headless Chromium, driven by Playwright, with an emulated Meta Quest 3 and tracked
// hands (iwer), against a real `thermode serve`: the right index tip entering the aluminium cube gives a touch on
// channel 1 within two rendered frames; 1000 enter/exit cycles leave no stuck contact; closing the page releases
// within the daemon's grace period. Every message the page's client sent and received is validated against
// docs/protocol.schema.json.
//
// Without /usr/bin/chromium the suite is skipped, unless THERMODE_REQUIRE_NODE_TESTS=1 (CI), where it fails.

import { after, before, test } from "node:test";
import assert from "node:assert/strict";
import { existsSync } from "node:fs";
import { chromium } from "playwright-core";
import { startStaticServer } from "../serve.js";
import { assertValid, httpJson, sleep, startDaemon } from "../../../clients/js/test/daemon.js";

const CHROMIUM = "/usr/bin/chromium";
// The dashboard test's flags (crates/thermode-serve/tests/integration/dashboard.rs).
const FLAGS = [
  "--headless",
  "--no-sandbox",
  "--disable-gpu",
  "--disable-quic",
  "--disable-background-networking",
  "--disable-component-update",
  "--disable-sync",
  "--no-first-run",
];
/** The daemon's grace period before a vanished client's contacts are released [s] (`serve --release-after`). */
const GRACE_S = 2;
/** The aluminium cube's centre and a point in the air beside it, in the scene (reference space) [m]. */
const IN_CUBE = [0, 1.0, -0.4];
const IN_AIR = [0, 1.2, -0.4];

const missing = !existsSync(CHROMIUM);
if (missing && process.env.THERMODE_REQUIRE_NODE_TESTS === "1") throw new Error(`${CHROMIUM} is missing: install Debian's chromium`);
const skip = missing ? `${CHROMIUM} is not installed (apt-get install chromium)` : false;

let daemon;
let web;
let browser;
let page;

before(async () => {
  if (skip) return;
  web = await startStaticServer();
  // At 1 kHz the loop applies a touch within a millisecond (at the default 100 Hz the measured touch came one to two
  // frames after the entry on this 2-core machine; the two-frame bound then has little margin under load).
  daemon = await startDaemon(["--allow-origin", web.base, "--release-after", String(GRACE_S)], { rateHz: 1000 });
  browser = await chromium.launch({ executablePath: CHROMIUM, args: FLAGS });
  page = await browser.newPage();
  const errors = [];
  page.on("pageerror", (error) => errors.push(error.message));
  page.on("console", (message) => {
    if (message.type() === "error") console.log(`page console: ${message.text()}`);
  });
  page.on("crash", () => console.log("the page crashed"));
  await page.goto(`${web.base}/index.html?emulate=1&daemon=${encodeURIComponent(daemon.url)}`);
  await page.waitForFunction(() => window.thermalApp || window.thermalAppError, null, { timeout: 30000 });
  assert.equal(await page.evaluate(() => window.thermalAppError ?? null), null, errors.join("\n"));
  await page.evaluate(installTestHooks);
  await page.evaluate(() => window.thermalApp.enterXR());
  await page.waitForFunction(() => window.thermalApp.contacts.fingers.every((f) => f.position !== null), null, { timeout: 30000 });
});

after(async () => {
  await browser?.close();
  web?.server.close();
  await daemon?.stop();
});

/** In the page: frame waits, the right tip placed anywhere, and every message of the client kept. */
function installTestHooks() {
  const app = window.thermalApp;
  const waiters = [];
  const update = app.contacts.update.bind(app.contacts);
  app.contacts.update = (frame, space) => {
    update(frame, space);
    for (const resolve of waiters.splice(0)) resolve(app.contacts.frame);
  };
  // What could stop the frames, kept for the failure message of a frame wait.
  const problems = [];
  window.addEventListener("error", (e) => problems.push(`error: ${e.message}`));
  window.addEventListener("unhandledrejection", (e) => problems.push(`rejection: ${e.reason}`));
  app.renderer.domElement.addEventListener("webglcontextlost", () => problems.push("WebGL context lost"));
  app.renderer.xr.addEventListener("sessionend", () => problems.push("XR session ended"));
  const messages = { sent: [], received: [] };
  app.client.on("sent", (m) => messages.sent.push(m));
  app.client.on("received", (m) => messages.received.push(m));
  const fingers = Object.fromEntries(app.contacts.fingers.map((f) => [f.handedness, f]));
  window.testHooks = {
    messages,
    fingers,
    problems,
    /** Resolves with the frame count after the next rendered frame; rejects after 10 s without one, saying why. */
    nextFrame: () =>
      new Promise((resolve, reject) => {
        const timer = setTimeout(() => {
          const state = { frame: app.contacts.frame, visibility: document.visibilityState, problems };
          reject(new Error(`no rendered frame within 10 s: ${JSON.stringify(state)}`));
        }, 10000);
        waiters.push((frame) => {
          clearTimeout(timer);
          resolve(frame);
        });
      }),
    /** Moves an emulated hand (default the right) so that its index tip lands on `target` from the next frame on. */
    placeTip([x, y, z], handedness = "right") {
      const hand = app.device.hands[handedness].position;
      const tip = fingers[handedness].position;
      hand.set(hand.x + x - tip.x, hand.y + y - tip.y, hand.z + z - tip.z);
    },
    /** Moves the right index tip to `target` and resolves once the daemon applied what it touches there. */
    placeTipAndWait(target) {
      const applied = window.testHooks.nextEvent("applied", 1);
      window.testHooks.placeTip(target);
      return applied;
    },
    /** Resolves with the first contact event of `kind` on `channel` from now on; rejects after 10 s, saying what
     * the contacts' state was. */
    nextEvent(kind, channel) {
      return new Promise((resolve, reject) => {
        const timer = setTimeout(() => {
          stop();
          const channels = [...app.contacts._channels].map(([c, st]) => [c, st.inFlight, st.applied?.name ?? null, st.desired?.name ?? null]);
          const state = { frame: app.contacts.frame, connected: app.client.connected, channels, tips: Object.values(fingers).map((f) => f.position.toArray()), problems };
          reject(new Error(`no ${kind} on channel ${channel} within 10 s: ${JSON.stringify(state)}`));
        }, 10000);
        const stop = app.contacts.on((e) => {
          if (e.kind === kind && e.channel === channel) {
            stop();
            clearTimeout(timer);
            resolve({ frame: e.frame, mesh: e.mesh?.name ?? null, reply: e.reply ?? null, atMs: performance.now() });
          }
        });
      });
    },
  };
}

/** The daemon's view of channel `channel`. */
async function channelState(channel) {
  return (await httpJson(daemon, "/api/status")).body.channels[channel];
}

test("the index tip entering the aluminium cube touches channel 1 within two rendered frames", { skip, timeout: 60000 }, async () => {
  const trials = await page.evaluate(
    async ([inCube, inAir]) => {
      const h = window.testHooks;
      const results = [];
      for (let trial = 0; trial < 20; trial++) {
        h.placeTip(inAir);
        await h.nextFrame();
        await new Promise((r) => setTimeout(r, 100));
        const applied = h.nextEvent("applied", 1);
        const entered = h.nextEvent("enter", 1);
        const movedFrame = window.thermalApp.contacts.frame;
        const movedMs = performance.now();
        h.placeTip(inCube);
        const [enter, touch] = await Promise.all([entered, applied]);
        results.push({ movedFrame, enterFrame: enter.frame, touchFrame: touch.frame, mesh: touch.mesh, reply: touch.reply, ms: touch.atMs - movedMs });
        h.placeTip(inAir);
        await h.nextEvent("applied", 1);
      }
      return results;
    },
    [IN_CUBE, IN_AIR],
  );
  for (const t of trials) {
    assert.equal(t.mesh, "aluminium cube");
    assert.equal(t.reply.request, "touch");
    assert.equal(t.reply.material, "aluminium");
    assert.equal(t.reply.channel, 1);
    assert.equal(t.enterFrame, t.movedFrame + 1, "the contact is seen in the first frame with the new pose");
    assert.ok(t.touchFrame - t.movedFrame <= 2, `touch applied ${t.touchFrame - t.movedFrame} frames after the tip entered: ${JSON.stringify(t)}`);
  }
  const frames = trials.map((t) => t.touchFrame - t.movedFrame);
  const ms = trials.map((t) => t.ms);
  console.log(`enter -> touch applied: frames ${Math.min(...frames)}..${Math.max(...frames)}, ms ${Math.min(...ms).toFixed(1)}..${Math.max(...ms).toFixed(1)} over ${trials.length} trials`);
  await page.evaluate((p) => window.testHooks.placeTipAndWait(p), IN_CUBE);
  const state = await channelState(1);
  assert.equal(state.contact, true, JSON.stringify(state));
  assert.equal(state.material, "aluminium");
  assert.equal((await channelState(0)).contact, false, "the left hand touches nothing");
  await page.evaluate((p) => window.testHooks.placeTipAndWait(p), IN_AIR);
  assert.equal((await channelState(1)).contact, false, "leaving the cube released it");
});

test("a material given by its properties, and the left index tip on channel 0", { skip, timeout: 60000 }, async () => {
  const [pine, wood] = await page.evaluate(async () => {
    const h = window.testHooks;
    const right = h.nextEvent("applied", 1);
    h.placeTip([-0.25, 1.0, -0.4]);
    const left = h.nextEvent("applied", 0);
    h.placeTip([0.25, 1.0, -0.4], "left");
    return Promise.all([right, left]);
  });
  // The pine board: k 0.12 W/(m·K), ρ 500 kg/m³, c 1600 J/(kg·K), 2 cm at 30 °C (src/main.js).
  assert.equal(pine.reply.material, "pine");
  assert.equal(pine.reply.object_temp_c, 30);
  assert.equal(wood.reply.material, "wood");
  const [right, left] = [await channelState(1), await channelState(0)];
  // The page's client reads the same status over its WebSocket (the page's origin is not the daemon's).
  const seenByPage = await page.evaluate(() => window.thermalApp.client.status());
  assertValid("Status", seenByPage);
  assert.equal(seenByPage.channels[1].material, "pine");
  assert.equal(right.material, "pine");
  assert.equal(right.object_temp_c, 30);
  assert.equal(left.material, "wood");
  await page.evaluate(async ([inAir]) => {
    const h = window.testHooks;
    const released = [h.nextEvent("applied", 1), h.nextEvent("applied", 0)];
    h.placeTip(inAir);
    h.placeTip([0.25, 1.3, -0.4], "left");
    await Promise.all(released);
  }, [IN_AIR]);
  assert.deepEqual((await httpJson(daemon, "/api/status")).body.contacts, []);
});

test("1000 enter/exit cycles leave no stuck contact, and every message is valid against the schema", { skip, timeout: 240000 }, async () => {
  const outcome = await page.evaluate(
    async ([inCube, inAir]) => {
      const h = window.testHooks;
      const contacts = window.thermalApp.contacts;
      let enters = 0;
      let exits = 0;
      const stop = contacts.on((e) => {
        if (e.channel !== 1) return;
        if (e.kind === "enter") enters += 1;
        if (e.kind === "exit") exits += 1;
      });
      const before = { ...contacts.stats };
      const started = performance.now();
      for (let cycle = 0; cycle < 1000; cycle++) {
        h.placeTip(inCube);
        await h.nextFrame();
        h.placeTip(inAir);
        await h.nextFrame();
      }
      const cyclesMs = performance.now() - started;
      while (!contacts.settled && performance.now() - started < cyclesMs + 10000) await new Promise((r) => setTimeout(r, 20));
      stop();
      const stats = Object.fromEntries(Object.entries(contacts.stats).map(([k, v]) => [k, v - before[k]]));
      return { enters, exits, stats, settled: contacts.settled, cyclesMs, messages: h.messages };
    },
    [IN_CUBE, IN_AIR],
  );
  const { enters, exits, stats, settled, cyclesMs, messages } = outcome;
  console.log(`1000 cycles in ${(cyclesMs / 1000).toFixed(1)} s: ${stats.touches} touches, ${stats.releases} releases sent, ${stats.throttled} paced, ${stats.errors} errors`);
  assert.equal(enters, 1000, "every entry seen");
  assert.equal(exits, 1000, "every exit seen");
  assert.ok(settled, "the daemon's state caught up with the finger's");
  assert.equal(stats.errors, 0, "no refusal (the pace stays under the daemon's rate cap)");
  assert.ok(stats.touches >= 1 && stats.touches === stats.releases, `touches ${stats.touches} and releases ${stats.releases} alternate`);
  const status = (await httpJson(daemon, "/api/status")).body;
  assert.deepEqual(status.contacts, [], "no stuck contact");
  assert.ok(status.channels.every((c) => !c.contact), JSON.stringify(status.channels.map((c) => c.contact)));
  for (const message of messages.sent) assertValid("ClientMessage", message);
  for (const message of messages.received) assertValid("Response", message);
  assert.ok(messages.sent.length >= 2 * stats.touches, `${messages.sent.length} messages sent`);
});

test("closing the page releases its contact within the daemon's grace period", { skip, timeout: 60000 }, async () => {
  await page.evaluate((p) => window.testHooks.placeTipAndWait(p), IN_CUBE);
  assert.equal((await channelState(1)).contact, true);
  const closedAt = performance.now();
  await page.close();
  // The socket closed between `closedAt` and `closeReturned` (page.close resolves once the page is gone).
  const closeReturned = performance.now();
  let lastSeenStart = null;
  let releasedAt = null;
  while (performance.now() - closedAt < (GRACE_S + 3) * 1000) {
    const pollStart = performance.now();
    if (!(await channelState(1)).contact) {
      releasedAt = performance.now();
      break;
    }
    lastSeenStart = pollStart;
    await sleep(10);
  }
  assert.notEqual(releasedAt, null, "the contact was never released");
  const releasedAfterMs = releasedAt - closedAt;
  console.log(
    `closing the page (${(closeReturned - closedAt).toFixed(0)} ms): released ${releasedAfterMs.toFixed(0)} ms after the close began, ${(releasedAt - closeReturned).toFixed(0)} ms after it ended, grace period ${GRACE_S} s`,
  );
  // Still touching when asked after the grace period had run from the socket's close would be a stuck contact.
  // The browser's network process closes the socket at about the time page.close() resolves (the release came up to
  // 47 ms after grace + close here, polls every 10 ms included): 250 ms are allowed for that on a loaded machine.
  const lastSeenMs = lastSeenStart - closeReturned;
  assert.ok(lastSeenMs <= GRACE_S * 1000 + 250, `contact still seen ${lastSeenMs} ms after the page had closed`);
  // And it was the daemon's grace release (at most a loop period early), not an earlier one.
  assert.ok(releasedAfterMs >= GRACE_S * 1000 - 20, `released ${releasedAfterMs} ms after the close, before the grace period`);
});
