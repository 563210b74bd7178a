// The package installed from the repository into a fresh folder (`npm install /path/to/clients/js`, as a user
// would, and as a packed copy with `--install-links`, which brings no `ws`: then the package's own WebSocket, or
// Node's) touches aluminium on a running `thermode serve` from a Node script there.

import { after, before, test } from "node:test";
import assert from "node:assert/strict";
import { execFileSync } from "node:child_process";
import { mkdtempSync, rmSync, writeFileSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import { REPO, startDaemon } from "./daemon.js";

const SCRIPT = `import { connect } from "thermode-client";
const client = await connect(process.argv[2], { reconnect: false });
const touched = await client.touch(1, "aluminium");
const status = await client.status();
const socket = client._socket.constructor.name;
await client.release(1);
await client.close();
console.log(JSON.stringify({ touched, contact: status.channels[1], socket }));
`;

let daemon;
before(async () => {
  daemon = await startDaemon();
});
after(async () => {
  await daemon?.stop();
});

/** Node's flags for its own WebSocket: none from Node 22 on, where it is global; the experimental flag before. */
const NODE_WEBSOCKET = Number(process.versions.node.split(".")[0]) >= 22 ? [] : ["--experimental-websocket"];

/** Installs the package into a fresh folder with `extra` npm options, runs the script there with the `node` flags,
 * returns its output. */
function installAndTouch(extra, node = []) {
  const folder = mkdtempSync(join(tmpdir(), "thermode-js-install-"));
  try {
    writeFileSync(join(folder, "package.json"), JSON.stringify({ name: "fresh", version: "1.0.0", private: true, type: "module" }));
    const npm = ["install", "--no-audit", "--no-fund", "--prefer-offline", ...extra, join(REPO, "clients/js")];
    execFileSync("npm", npm, { cwd: folder, stdio: "pipe", timeout: 120000 });
    writeFileSync(join(folder, "touch.mjs"), SCRIPT);
    const env = { ...process.env };
    delete env.NODE_PATH;
    const output = execFileSync("node", [...node, "touch.mjs", daemon.url], { cwd: folder, env, timeout: 30000 }).toString();
    return JSON.parse(output.trim().split("\n").at(-1));
  } finally {
    rmSync(folder, { recursive: true, force: true });
  }
}

const WAYS = [
  ["linked", [], [], "WebSocket"],
  ["copied, without ws: its own WebSocket", ["--install-links"], [], "NodeWebSocket"],
  ["copied, without ws: Node's WebSocket", ["--install-links"], NODE_WEBSOCKET, "WebSocket"],
];
for (const [how, extra, node, socketClass] of WAYS) {
  test(`installed from the repository (${how}) into a fresh folder, it touches aluminium from Node`, () => {
    const { touched, contact, socket } = installAndTouch(extra, node);
    assert.equal(socket, socketClass, "the WebSocket the client chose");
    assert.equal(touched.type, "ok");
    assert.equal(touched.request, "touch");
    assert.equal(touched.material, "aluminium");
    assert.equal(contact.contact, true, JSON.stringify(contact));
    assert.equal(contact.material, "aluminium");
  });
}
