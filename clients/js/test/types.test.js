// The hand-written declarations (src/index.d.ts) against the code: every runtime export is declared, and a typical
// use of the client (test/types/use.ts) type-checks under `tsc --strict`.

import { test } from "node:test";
import assert from "node:assert/strict";
import { execFileSync } from "node:child_process";
import { readFileSync } from "node:fs";
import { createRequire } from "node:module";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import * as client from "../src/index.js";

const HERE = dirname(fileURLToPath(import.meta.url));

test("every export of the module is declared in index.d.ts, and nothing more", () => {
  const declarations = readFileSync(join(HERE, "../src/index.d.ts"), "utf8");
  const declared = [...declarations.matchAll(/^export declare (?:const|function|class) (\w+)/gm)].map((m) => m[1]);
  assert.deepEqual(declared.sort(), Object.keys(client).sort());
});

/** Runs `tsc --strict` on `file`; returns its output and whether it passed. */
function typeCheck(file) {
  const tsc = createRequire(import.meta.url).resolve("typescript/bin/tsc");
  const args = [tsc, "--noEmit", "--strict", "--module", "nodenext", "--moduleResolution", "nodenext", "--target", "es2022", join(HERE, "types", file)];
  try {
    return { ok: true, output: execFileSync(process.execPath, args, { stdio: "pipe", timeout: 120000 }).toString() };
  } catch (error) {
    return { ok: false, output: `${error.stdout}${error.stderr}` };
  }
}

test("a typical use of the client type-checks with tsc --strict, and misuse does not", () => {
  const use = typeCheck("use.ts");
  assert.ok(use.ok, use.output);
  const misuse = typeCheck("misuse.ts");
  assert.equal(misuse.ok, false);
  const errors = misuse.output.split("\n").filter((line) => line.includes("error TS"));
  assert.deepEqual(errors.map((line) => line.match(/misuse\.ts\((\d+),/)?.[1]), ["4", "5", "6"], misuse.output);
});
