// Test fixtures: `thermode serve` on the simulated display on free ports with its own state directory, and the
// published protocol schema (docs/protocol.schema.json) compiled for draft 2020-12 validation.
//
// The binary: $THERMODE_BIN (set by the Rust test that runs these suites), else the repository's
// target/debug/thermode, else target/release/thermode.

import { spawn } from "node:child_process";
import { accessSync, constants, mkdtempSync, readFileSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { dirname, join, resolve } from "node:path";
import { fileURLToPath } from "node:url";
import Ajv2020 from "ajv/dist/2020.js";

export const REPO = resolve(dirname(fileURLToPath(import.meta.url)), "../../..");

/** The thermode binary to test. */
export function thermodeBinary() {
  const candidates = [process.env.THERMODE_BIN, join(REPO, "target/debug/thermode"), join(REPO, "target/release/thermode")];
  for (const candidate of candidates) {
    if (!candidate) continue;
    try {
      accessSync(candidate, constants.X_OK);
      return candidate;
    } catch {
      // the next one
    }
  }
  throw new Error("no thermode binary: build it (`cargo build -p thermode`) or set THERMODE_BIN");
}

/** A running `thermode serve`: `url` (WebSocket), `httpBase`, `port`, `stop()`. `args`: extra serve options;
 * `port`: the HTTP port (default 0: a free one); `rateHz`: the loop rate [Hz] (default 100, serve's). */
export async function startDaemon(args = [], { port = 0, rateHz = 100 } = {}) {
  const state = mkdtempSync(join(tmpdir(), "thermode-state-"));
  const all = ["serve", "--port", String(port), "--no-osc", "--no-realtime", "--rate", String(rateHz), "--state-dir", state, ...args];
  const child = spawn(thermodeBinary(), all, { stdio: ["ignore", "pipe", "pipe"] });
  let banner = "";
  const url = await new Promise((resolveUrl, reject) => {
    const timer = setTimeout(() => reject(new Error(`thermode serve printed no WebSocket address:\n${banner}`)), 30000);
    const read = (chunk) => {
      banner += chunk.toString();
      const found = banner.match(/ws:\/\/\S+\/api\/ws/);
      if (found) {
        clearTimeout(timer);
        resolveUrl(found[0]);
      }
    };
    child.stdout.on("data", read);
    child.stderr.on("data", (chunk) => {
      banner += chunk.toString();
    });
    child.on("exit", (code) => reject(new Error(`thermode serve exited (${code}):\n${banner}`)));
  });
  const bound = Number(new URL(url).port);
  const exited = new Promise((done) => child.on("exit", done));
  return {
    url,
    port: bound,
    httpBase: `http://127.0.0.1:${bound}`,
    child,
    async stop() {
      child.kill("SIGTERM");
      const timer = setTimeout(() => child.kill("SIGKILL"), 10000);
      await exited;
      clearTimeout(timer);
      rmSync(state, { recursive: true, force: true });
    },
  };
}

/** `GET path` of a daemon as JSON. */
export async function httpJson(daemon, path, headers = {}) {
  const response = await fetch(daemon.httpBase + path, { headers });
  return { status: response.status, body: await response.json() };
}

const SCHEMA = JSON.parse(readFileSync(join(REPO, "docs/protocol.schema.json"), "utf8"));
const ajv = new Ajv2020({ strict: false, validateFormats: false, allErrors: true });
ajv.addSchema(SCHEMA, "protocol");

/** Asserts that `message` is an instance of the schema's `$defs/definition`, printing the message and the errors. */
export function assertValid(definition, message) {
  const validate = ajv.getSchema(`protocol#/$defs/${definition}`);
  if (!validate(message)) {
    const errors = validate.errors.slice(0, 4).map((e) => `${e.instancePath} ${e.message}`);
    throw new Error(`${definition}: ${JSON.stringify(message).slice(0, 400)} -> ${errors.join("; ")}`);
  }
}

/** Whether `message` is an instance of `$defs/definition`. */
export function isValid(definition, message) {
  return ajv.getSchema(`protocol#/$defs/${definition}`)(message);
}

/** Resolves after `ms` milliseconds. */
export const sleep = (ms) => new Promise((done) => setTimeout(done, ms));
