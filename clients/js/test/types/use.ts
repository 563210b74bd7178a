// Compiled (not run) by test/types.test.js with `tsc --strict`: the declarations type a typical use of the client.
import { connect, ThermodeError, Client, type Telemetry } from "../../src/index.js";
async function main(): Promise<void> {
  const c: Client = await connect("ws://127.0.0.1:8765/api/ws", { token: "x", reconnect: { initialDelayMs: 100 } });
  const r = await c.touch(1, "aluminium", 20);
  console.log(r.tick, r.request);
  await c.touch(2, { conductivity_w_mk: 1, density_kg_m3: 2, specific_heat_j_kgk: 3 });
  c.on("telemetry", (t: Telemetry) => t.channels[0].skin_c);
  c.on("reconnecting", ({ attempt, delayMs }) => attempt + delayMs);
  await c.program({ 0: [{ to_c: 30, rate_c_s: 1, until: "response" }, { hold_s: 2 }] });
  const e = await c.waitForResponse({ channel: 0 });
  try { await c.stopAll(); } catch (err) { if (err instanceof ThermodeError && err.code === "rate_limited") console.log(err.detail); }
  console.log(e.tick, (await c.status()).limits);
}
main();
