// The client against a real `thermode serve` on the simulated display: every request, its reply and the errors;
// every message sent and received, and the status, validated against docs/protocol.schema.json; a program ended by
// a response; the token; reconnection with backoff after the daemon went away and came back on the same port.

import { after, before, test } from "node:test";
import assert from "node:assert/strict";
import { Client, ThermodeError, backoffDelayMs } from "../src/index.js";
import { NodeWebSocket } from "../src/node-websocket.js";
import { assertValid, httpJson, isValid, sleep, startDaemon } from "./daemon.js";

let daemon;
before(async () => {
  daemon = await startDaemon();
});
after(async () => {
  await daemon?.stop();
});

/** A client whose every message, both ways, is kept. */
async function recordedClient(url, options = {}) {
  const client = await Client.connect(url, { reconnect: false, ...options });
  const sent = [];
  const received = [];
  client.on("sent", (m) => sent.push(m));
  client.on("received", (m) => received.push(m));
  return { client, sent, received };
}

/** Rejects unless `promise` rejects with a daemon's ThermodeError of `code`. */
async function refusedWith(promise, code) {
  await assert.rejects(promise, (error) => {
    assert.ok(error instanceof ThermodeError, `not a ThermodeError: ${error}`);
    assert.equal(error.code, code, `code of ${error.message}`);
    assert.equal(error.fromDaemon, true);
    return true;
  });
}

/** The first telemetry frames: resolves with `count` of them. */
function frames(client, count) {
  return new Promise((resolve) => {
    const got = [];
    const stop = client.on("telemetry", (frame) => {
      got.push(frame);
      if (got.length === count) {
        stop();
        resolve(got);
      }
    });
  });
}

test("a session both ways is valid against the published schema, and refusals are typed errors", async () => {
  const { client, sent, received } = await recordedClient(daemon.url);
  const touched = await client.touch(1, "aluminium", 20);
  assert.equal(touched.request, "touch");
  assert.equal(touched.material, "aluminium");
  assert.equal(touched.object_temp_c, 20);
  const contact = (await client.status()).channels[1];
  assert.equal(contact.contact, true, "the status after the reply shows the contact");
  assert.equal(contact.material, "aluminium");
  await client.touch(2, { conductivity_w_mk: 0.2, density_kg_m3: 1200, specific_heat_j_kgk: 1500, name: "pla" });
  const arriving = frames(client, 20);
  await client.subscribe(20);
  const telemetry = await arriving;
  await client.unsubscribe();
  // Aluminium at 20 °C draws heat from a 32 °C fingertip: the target receptor temperature falls during the second
  // of telemetry (it starts near 32 °C at rest and a metal contact cools it by degrees within seconds).
  const targets = telemetry.map((f) => f.channels[1].target_skin_c);
  assert.ok(targets.at(-1) < targets[0] - 0.5, `aluminium cools the finger: ${targets[0]} -> ${targets.at(-1)} °C`);
  await client.setpoint(3, 30.0, 2.0);
  const marked = await client.marker("trial 1", 1);
  assert.equal(typeof marked.time_s, "number");
  const status = await client.request({ type: "status" });
  assert.equal(status.type, "status");
  await refusedWith(client.touch(9, "wood"), "unknown_channel");
  await refusedWith(client.touch(0, "kryptonite"), "unknown_material");
  await refusedWith(client.setpoint(0, 80, 1), "bad_value");
  await refusedWith(client.request({ type: "touch", channel: 0, material: "wood", colour: "red" }), "unknown_field");
  await client.clearFault(0);
  await client.release(1);
  await client.stopAll();
  await client.close();
  const kinds = new Set(received.map((m) => m.type));
  for (const kind of ["ok", "error", "status", "telemetry"]) assert.ok(kinds.has(kind), `no ${kind} among ${[...kinds]}`);
  for (const message of sent) {
    if (message.colour === undefined) assertValid("ClientMessage", message);
  }
  assert.equal(isValid("ClientMessage", sent.find((m) => m.colour !== undefined)), false, "the schema refuses a stray field");
  for (const message of received) assertValid("Response", message);
  for (const [path, definition] of [["/api/status", "Status"], ["/api/materials", "MaterialList"], ["/api/history", "History"]]) {
    assertValid(definition, (await httpJson(daemon, path)).body);
  }
});

test("a program's until-response ramp ends at a response, and the waits see its events", async () => {
  const { client, sent, received } = await recordedClient(daemon.url);
  const started = await client.program({ 0: [{ to_c: 32 }, { to_c: 0, rate_c_s: 2, until: "response" }, { to_c: 32, rate_c_s: 5 }] });
  assert.deepEqual(started.channels, [0]);
  // The simulated display's range ends at 15 °C (docs/api.md): the 0 °C target is clipped there, and said so.
  assert.equal(started.cutoff_c, 15);
  const ramp = await client.waitForEvent("segment_start", { channel: 0, afterTick: started.start_tick, timeoutMs: 5000 });
  assert.equal(ramp.segment, 0);
  await sleep(1000);
  const pressed = await client.response(0);
  assert.equal(pressed.ended_segment, 1);
  const event = await client.waitForResponse({ channel: 0, timeoutMs: 5000 });
  assert.equal(event.tick, pressed.tick, "the event is on the reply's tick");
  assert.ok(pressed.setpoint_c < 32 && pressed.setpoint_c > 15, `the ramp had gone down: ${pressed.setpoint_c} °C`);
  const end = await client.waitForProgramEnd({ channel: 0, timeoutMs: 10000 });
  assert.ok(end.tick > pressed.tick);
  const rated = await client.response(0, "rating", 55);
  assert.equal(rated.value, 55);
  assert.equal(rated.ended_segment, null, "no until-response segment ran");
  await client.program({ 2: [{ hold_s: 30 }] });
  const stopped = await client.programStop(2);
  assert.equal(stopped.channel, 2);
  await refusedWith(client.program({ 0: Array.from({ length: 1000 }, () => ({ hold_s: 0 })) }), "bad_value");
  await client.close();
  for (const message of sent.filter((m) => m.channels?.[0]?.length !== 1000)) assertValid("ClientMessage", message);
  for (const message of received) assertValid("Response", message);
  assert.ok(received.some((m) => m.type === "program_event"));
});

test("with a token: refused without it, accepted with it, over every WebSocket the client may use", async () => {
  const guarded = await startDaemon(["--token", "s3cret-token"]);
  try {
    await assert.rejects(Client.connect(guarded.url, { reconnect: false }), (e) => e instanceof ThermodeError && e.code === "connection_closed");
    const unauthorized = new Client(guarded.url, { reconnect: false });
    await assert.rejects(unauthorized.status(), (e) => e.code === "unauthorized" && e.fromDaemon);
    const sockets = [{}, { WebSocket: NodeWebSocket, webSocketTakesHeaders: true }, { WebSocket: NodeWebSocket }];
    for (const options of sockets) {
      const client = await Client.connect(guarded.url, { token: "s3cret-token", reconnect: false, ...options });
      const reply = await client.touch(0, "wood");
      assert.equal(reply.material, "wood");
      assert.equal((await client.status()).auth.token_required, true);
      await client.release(0);
      await client.close();
    }
  } finally {
    await guarded.stop();
  }
});

test("the built-in Node WebSocket carries a whole session, telemetry included", async () => {
  const { client, received } = await recordedClient(daemon.url, { WebSocket: NodeWebSocket, webSocketTakesHeaders: true });
  await client.touch(4, "steel");
  const arriving = frames(client, 5);
  await client.subscribe(50);
  assert.equal((await arriving).length, 5);
  await client.unsubscribe();
  await client.release(4);
  await client.close();
  for (const message of received) assertValid("Response", message);
});

test("after the daemon goes away the client reconnects with exponential backoff, says so and subscribes again", async () => {
  const first = await startDaemon();
  const policy = { initialDelayMs: 100, factor: 2, maxDelayMs: 800 };
  const client = await Client.connect(first.url, { reconnect: policy, timeoutMs: 3000 });
  const said = [];
  for (const name of ["disconnected", "reconnecting", "reconnected"]) client.on(name, (value) => said.push({ name, ...value }));
  await client.subscribe(20);
  await first.stop();
  await sleep(1800);
  await refusedWhileAway(client);
  const second = await startDaemon([], { port: first.port });
  try {
    const back = new Promise((resolve) => client.on("reconnected", resolve));
    const { attempts } = await back;
    const telemetry = await frames(client, 3);
    assert.equal(telemetry.length, 3, "the subscription was renewed");
    assert.equal((await client.touch(1, "aluminium")).material, "aluminium");
    assert.equal(said[0].name, "disconnected");
    const waits = said.filter((s) => s.name === "reconnecting");
    assert.equal(waits.length, attempts);
    // 100, 200, 400, 800, 800, … ms: computed here from the policy, independently of the client's helper.
    waits.forEach((wait, i) => assert.equal(wait.delayMs, Math.min(800, 100 * 2 ** i), `attempt ${i + 1}`));
    assert.ok(attempts >= 4, `${attempts} attempts in the ~2 s the daemon was away`);
    assert.equal(backoffDelayMs({ ...policy, maxAttempts: Infinity }, 3), 400);
    await client.close();
  } finally {
    await second.stop();
  }
});

/** While the daemon is away a request fails at once with `connection_closed`. */
async function refusedWhileAway(client) {
  assert.equal(client.connected, false);
  await assert.rejects(client.touch(0, "wood"), (e) => e.code === "connection_closed" && !e.fromDaemon);
}
