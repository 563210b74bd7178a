// A tiny static server for the example (no build step): serves this folder, its node_modules included, on
// 127.0.0.1. `node serve.js [PORT]` (default 8080) prints the page's address; the tests import `startStaticServer`.

import { createServer } from "node:http";
import { readFile, realpath } from "node:fs/promises";
import { dirname, extname, join, normalize, sep } from "node:path";
import { fileURLToPath } from "node:url";

const ROOT = dirname(fileURLToPath(import.meta.url));
const TYPES = { ".html": "text/html", ".js": "text/javascript", ".mjs": "text/javascript", ".json": "application/json", ".css": "text/css" };

/** Serves `root` on 127.0.0.1:`port` (0: a free one); resolves with the server and its base address. Paths that
 * leave `root` are refused (node_modules' links to sibling packages are followed, as npm made them). */
export async function startStaticServer(root = ROOT, port = 0) {
  const server = createServer(async (request, response) => {
    const path = normalize(decodeURIComponent(new URL(request.url, "http://x").pathname));
    if (path.split(sep).includes("..")) return answer(response, 403, "forbidden");
    const file = join(root, path.endsWith("/") ? `${path}index.html` : path);
    try {
      const body = await readFile(await realpath(file));
      response.writeHead(200, { "Content-Type": TYPES[extname(file)] ?? "application/octet-stream", "Cache-Control": "no-store" });
      response.end(body);
    } catch {
      answer(response, 404, "not found");
    }
  });
  await new Promise((resolve) => server.listen(port, "127.0.0.1", resolve));
  return { server, base: `http://127.0.0.1:${server.address().port}` };
}

function answer(response, status, text) {
  response.writeHead(status, { "Content-Type": "text/plain" });
  response.end(text);
}

if (process.argv[1] === fileURLToPath(import.meta.url)) {
  const { base } = await startStaticServer(ROOT, Number(process.argv[2] ?? 8080));
  console.log(`thermode WebXR example: ${base}/  (start the daemon with: thermode serve --allow-origin ${base})`);
}
