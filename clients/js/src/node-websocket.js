// A small WebSocket client for Node (RFC 6455, text frames), used when neither the `ws` package nor a global
// WebSocket is there (Node 18–21 without `ws`), so that the package works with no dependency installed. It offers
// the part of the browser WebSocket interface the client uses: `addEventListener`/`removeEventListener` for `open`,
// `message`, `close` and `error`, `send(text)`, `close()` and `readyState`; an optional `{headers}` argument as `ws`
// takes. Never imported in a browser.

import { request } from "node:http";
import { request as requestTls } from "node:https";
import { createHash, randomBytes } from "node:crypto";

const GUID = "258EAFA5-E914-47DA-95CA-C5AB0DC85B11";
/** Largest frame accepted from the daemon [bytes] (its own largest message is far below). */
const MAX_FRAME_BYTES = 64 * 1024 * 1024;

export class NodeWebSocket {
  /** Opens `url` (`ws:` or `wss:`); `options.headers`: extra handshake headers (e.g. Authorization). */
  constructor(url, options = {}) {
    this.readyState = 0;
    this._listeners = { open: new Set(), message: new Set(), close: new Set(), error: new Set() };
    this._buffer = Buffer.alloc(0);
    this._fragments = [];
    this._closeSent = false;
    const target = new URL(url);
    const key = randomBytes(16).toString("base64");
    const send = target.protocol === "wss:" ? requestTls : request;
    const req = send({
      hostname: target.hostname,
      port: target.port || (target.protocol === "wss:" ? 443 : 80),
      path: target.pathname + target.search,
      headers: { Connection: "Upgrade", Upgrade: "websocket", "Sec-WebSocket-Version": "13", "Sec-WebSocket-Key": key, ...(options.headers ?? {}) },
    });
    req.on("upgrade", (response, socket, head) => this._upgraded(response, socket, head, key));
    req.on("response", (response) => this._fail(new Error(`the handshake got HTTP ${response.statusCode}`)));
    req.on("error", (error) => this._fail(error));
    req.end();
  }

  addEventListener(name, listener) {
    this._listeners[name]?.add(listener);
  }

  removeEventListener(name, listener) {
    this._listeners[name]?.delete(listener);
  }

  /** Sends one text frame. */
  send(text) {
    if (this.readyState !== 1) throw new Error("the WebSocket is not open");
    this._socket.write(frame(0x1, Buffer.from(text, "utf8")));
  }

  /** Starts the closing handshake (the socket ends when the daemon answers, or after 2 s). */
  close(code = 1000) {
    if (this.readyState >= 2) return;
    if (this.readyState === 0) return this._fail(new Error("closed before it opened"));
    this.readyState = 2;
    this._sendClose(code);
    setTimeout(() => this._socket.destroy(), 2000).unref();
  }

  _upgraded(response, socket, head, key) {
    const accept = createHash("sha1").update(key + GUID).digest("base64");
    if (response.headers["sec-websocket-accept"] !== accept) {
      socket.destroy();
      return this._fail(new Error("the handshake's Sec-WebSocket-Accept is wrong"));
    }
    this._socket = socket;
    socket.setNoDelay(true);
    socket.on("data", (chunk) => this._data(chunk));
    socket.on("close", () => this._finish(1006, ""));
    socket.on("error", () => {});
    this.readyState = 1;
    this._dispatch("open", { type: "open" });
    if (head.length > 0) this._data(head);
  }

  _data(chunk) {
    this._buffer = Buffer.concat([this._buffer, chunk]);
    for (;;) {
      const parsed = parseFrame(this._buffer);
      if (parsed === null) return;
      if (parsed.error) {
        this._socket.destroy();
        return this._finish(1002, parsed.error);
      }
      this._buffer = this._buffer.subarray(parsed.length);
      this._frame(parsed);
    }
  }

  _frame({ fin, opcode, payload }) {
    if (opcode === 0x9) return this._socket.write(frame(0xa, payload));
    if (opcode === 0x8) {
      const code = payload.length >= 2 ? payload.readUInt16BE(0) : 1005;
      this._sendClose(code === 1005 ? 1000 : code);
      this._socket.end();
      return this._finish(code, payload.subarray(2).toString("utf8"));
    }
    if (opcode === 0x1 || opcode === 0x2 || opcode === 0x0) {
      this._fragments.push(payload);
      if (!fin) return;
      const data = Buffer.concat(this._fragments).toString("utf8");
      this._fragments = [];
      this._dispatch("message", { type: "message", data });
    }
  }

  _sendClose(code) {
    if (this._closeSent) return;
    this._closeSent = true;
    const body = Buffer.alloc(2);
    body.writeUInt16BE(code, 0);
    this._socket.write(frame(0x8, body));
  }

  _fail(error) {
    if (this.readyState === 3) return;
    this._dispatch("error", { type: "error", message: error.message, error });
    this._finish(1006, error.message);
  }

  _finish(code, reason) {
    if (this.readyState === 3) return;
    this.readyState = 3;
    this._dispatch("close", { type: "close", code, reason });
  }

  _dispatch(name, event) {
    for (const listener of [...this._listeners[name]]) listener(event);
  }
}

/** A masked client frame with `opcode` and `payload`. */
function frame(opcode, payload) {
  const length = payload.length;
  const header = length < 126 ? Buffer.alloc(2) : length < 65536 ? Buffer.alloc(4) : Buffer.alloc(10);
  header[0] = 0x80 | opcode;
  if (length < 126) header[1] = 0x80 | length;
  else if (length < 65536) {
    header[1] = 0x80 | 126;
    header.writeUInt16BE(length, 2);
  } else {
    header[1] = 0x80 | 127;
    header.writeBigUInt64BE(BigInt(length), 2);
  }
  const mask = randomBytes(4);
  const masked = Buffer.alloc(length);
  for (let i = 0; i < length; i++) masked[i] = payload[i] ^ mask[i & 3];
  return Buffer.concat([header, mask, masked]);
}

/** The first whole frame of `buffer` ({fin, opcode, payload, length}), null when incomplete, {error} when invalid. */
function parseFrame(buffer) {
  if (buffer.length < 2) return null;
  const fin = (buffer[0] & 0x80) !== 0;
  const opcode = buffer[0] & 0x0f;
  const masked = (buffer[1] & 0x80) !== 0;
  let length = buffer[1] & 0x7f;
  let offset = 2;
  if (length === 126) {
    if (buffer.length < 4) return null;
    length = buffer.readUInt16BE(2);
    offset = 4;
  } else if (length === 127) {
    if (buffer.length < 10) return null;
    length = Number(buffer.readBigUInt64BE(2));
    offset = 10;
  }
  if (masked) return { error: "a server frame was masked" };
  if (length > MAX_FRAME_BYTES) return { error: "a frame above 64 MiB" };
  if (buffer.length < offset + length) return null;
  return { fin, opcode, payload: buffer.subarray(offset, offset + length), length: offset + length };
}
