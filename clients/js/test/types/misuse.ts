// Compiled by test/types.test.js, which expects exactly these errors: the declarations refuse misuse.
import { connect } from "../../src/index.js";
const c = await connect("ws://127.0.0.1:8765/api/ws");
await c.touch("1", "aluminium"); // a channel is a number
await c.program({ 0: [{ hold_s: "2" }] }); // a hold lasts a number of seconds
c.on("reconnecting", ({ attempts }) => attempts); // `reconnecting` carries attempt and delayMs
