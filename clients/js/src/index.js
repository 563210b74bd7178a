// The JavaScript client of the thermode contact API (docs/api.md): one WebSocket connection to `thermode serve`,
// for browsers (the global WebSocket, no dependency) and Node (the `ws` package, or Node's own WebSocket).
//
// Every request gets a fresh numeric `id`; its reply (matched by that id) resolves the request's promise, or rejects
// it with a `ThermodeError` carrying the daemon's error code. Telemetry, program events and daemon events go to
// listeners (`client.on(...)`). A connection that drops unasked is opened again with exponential backoff, and the
// client says so (`disconnected`, `reconnecting`, `reconnected` events); a subscription is renewed on the new
// connection. Contacts are not renewed: the daemon releases a vanished client's contacts after its grace period,
// and touching again is the application's decision.

/** Milliseconds a request waits for its reply before a `timeout` error. Default 5000 (the daemon answers within a
 * loop tick, or after its own 1 s reply wait with `busy`). */
export const DEFAULT_TIMEOUT_MS = 5000;

/** Most segments of one channel's program (the daemon refuses more, naming the limit). */
export const MAX_SEGMENTS = 999;

/** Program events kept for `waitForEvent` before the oldest are dropped. */
const EVENT_BUFFER_LEN = 10000;

/** Default reconnection policy: first wait [ms], factor per attempt, longest wait [ms], attempts (Infinity: never
 * give up). */
export const DEFAULT_RECONNECT = Object.freeze({ initialDelayMs: 250, factor: 2, maxDelayMs: 10000, maxAttempts: Infinity });

/** The daemon refused a request (nothing changed), or the client failed (`timeout`, `connection_closed`, `http`).
 * `code`: the daemon's error code (docs/api.md "Error codes") or the client's own; `fromDaemon`: whether the daemon
 * sent it; `requestId` and `request` (its type) say which request it answers. */
export class ThermodeError extends Error {
  constructor(code, message, { fromDaemon = false, requestId = null, request = null } = {}) {
    super(`${code}: ${message}`);
    this.name = "ThermodeError";
    this.code = code;
    this.detail = message;
    this.fromDaemon = fromDaemon;
    this.requestId = requestId;
    this.request = request;
  }
}

/** The next wait [ms] of a reconnection policy before attempt `attempt` (1, 2, …): initial × factor^(attempt−1),
 * capped at the policy's maximum. */
export function backoffDelayMs(policy, attempt) {
  const delay = policy.initialDelayMs * policy.factor ** (attempt - 1);
  return Math.min(policy.maxDelayMs, delay);
}

/** The HTTP address of a daemon's path (`/api/status`) from its WebSocket address. */
export function httpUrl(wsUrl, path) {
  const url = new URL(wsUrl);
  url.protocol = url.protocol === "wss:" ? "https:" : "http:";
  url.pathname = path;
  url.search = "";
  url.hash = "";
  return url.toString();
}

/** The WebSocket constructor of this platform and whether it takes handshake headers: in a browser the global one;
 * in Node the `ws` package when installed, else Node's global WebSocket (Node 22+) when no token needs a header, else
 * the package's own small one (`node-websocket.js`), so that the package runs with no dependency installed. */
async function webSocketClass(needsHeaders) {
  const isNode = typeof process !== "undefined" && process.versions != null && process.versions.node != null;
  if (!isNode) return { Socket: globalThis.WebSocket, headers: false };
  try {
    const module = await import("ws");
    return { Socket: module.WebSocket ?? module.default, headers: true };
  } catch {
    // not installed: the next one
  }
  if (!needsHeaders && typeof globalThis.WebSocket === "function") return { Socket: globalThis.WebSocket, headers: false };
  const { NodeWebSocket } = await import("./node-websocket.js");
  return { Socket: NodeWebSocket, headers: true };
}

/** A connection to `thermode serve`. Create it with `await Client.connect(url, options)`. */
export class Client {
  /** Use `Client.connect`. `url`: the daemon's WebSocket address (`ws://127.0.0.1:8765/api/ws`); `options`:
   * `token` (the daemon's `--token`, default none), `timeoutMs` (reply wait, default 5000), `reconnect` (false, or a
   * policy like `DEFAULT_RECONNECT`, the default), `WebSocket` (a constructor to use instead of the platform's;
   * `webSocketTakesHeaders` says whether it takes `{headers}` as `ws` does). */
  constructor(url, options = {}) {
    this.url = url;
    this._webSocket = options.WebSocket ? { Socket: options.WebSocket, headers: options.webSocketTakesHeaders === true } : null;
    this.token = options.token ?? null;
    this.timeoutMs = options.timeoutMs ?? DEFAULT_TIMEOUT_MS;
    this.reconnectPolicy = options.reconnect === false ? null : { ...DEFAULT_RECONNECT, ...(options.reconnect ?? {}) };
    this._nextId = 1;
    this._waiting = new Map();
    this._listeners = new Map();
    this._events = [];
    this._eventWaiters = new Set();
    this._subscribedHz = null;
    this._closedByUser = false;
    this._socket = null;
    this._reconnectTimer = null;
  }

  /** Opens a connection and resolves once it is open (rejects with `connection_closed` when it cannot open). */
  static async connect(url, options = {}) {
    const client = new Client(url, options);
    await client._open();
    return client;
  }

  // -- requests -------------------------------------------------------------------------------------------------

  /** Touch `material` on `channel`: a library name (`GET /api/materials`), or an object of material properties
   * (`conductivity_w_mk`, `density_kg_m3`, `specific_heat_j_kgk`, optional `thickness_m` [m] and `name`).
   * `objectTempC`: the object's temperature [°C] (default: the daemon's room temperature, 23). */
  touch(channel, material, objectTempC) {
    const message = { type: "touch", channel };
    if (typeof material === "string") message.material = material;
    else message.properties = { ...material };
    if (objectTempC !== undefined && objectTempC !== null) message.object_temp_c = objectTempC;
    return this.request(message);
  }

  /** Let go: `channel` renders air again. */
  release(channel) {
    return this.request({ type: "release", channel });
  }

  /** Direct mode: the display of `channel` ramps to `tempC` [°C] at `rateCPerS` [°C/s] through the safety envelope
   * (its range and rate limit are `status().limits`). */
  setpoint(channel, tempC, rateCPerS) {
    return this.request({ type: "setpoint", channel, temp_c: tempC, rate_c_s: rateCPerS });
  }

  /** Clear the latched safety fault of `channel` (refused with `device_fault` while its cause persists). */
  clearFault(channel) {
    return this.request({ type: "clear_fault", channel });
  }

  /** Release every channel and hold every drive at 0 A until that channel's next command. */
  stopAll() {
    return this.request({ type: "stop_all" });
  }

  /** An event marker (e.g. a trial start), optionally on `channel`; the reply carries the daemon's loop `time_s`. */
  marker(text, channel) {
    const message = { type: "marker", text };
    if (channel !== undefined && channel !== null) message.channel = channel;
    return this.request(message);
  }

  /** A stimulus program: `channels` maps each channel (number or string key) to its segments (at most 999):
   * `{to_c, rate_c_s}` a ramp, `{to_c}` a step, `{hold_s}` a hold; a ramp or hold may add `until: "response"`.
   * The reply has `start_tick`, `start_time_s`, `cutoff_c` and `cutoffs`. This connection then receives the
   * program's events (`waitForEvent`). */
  program(channels) {
    const entries = channels instanceof Map ? [...channels.entries()] : Object.entries(channels);
    const body = {};
    for (const [channel, segments] of entries) body[String(channel)] = segments.map((segment) => ({ ...segment }));
    return this.request({ type: "program", channels: body });
  }

  /** End `channel`'s program; its set-point holds where the program left it. */
  programStop(channel) {
    return this.request({ type: "program_stop", channel });
  }

  /** A participant's response on `channel`: `kind` "button" (default), or "rating" with `value` 0–100. The reply
   * carries the tick it took effect on and the plate there (`sensor_c`, `plate_estimate_c`, `setpoint_c`) and the
   * `until: response` segment it ended (`ended_segment`, else null). */
  response(channel, kind = "button", value) {
    const message = { type: "response", channel, kind };
    if (value !== undefined && value !== null) message.value = value;
    return this.request(message);
  }

  /** Telemetry at `rateHz` (0.01–100, at most the loop rate) to the `telemetry` listeners until `unsubscribe()`;
   * renewed after a reconnection. */
  async subscribe(rateHz) {
    const reply = await this.request({ type: "subscribe", rate_hz: rateHz });
    this._subscribedHz = rateHz;
    return reply;
  }

  /** Stop the telemetry of `subscribe`. */
  async unsubscribe() {
    this._subscribedHz = null;
    return this.request({ type: "unsubscribe" });
  }

  /** `GET /api/status` of the same daemon (channels, contacts, limits, loop statistics, …). A browser page of
   * another origin than the daemon's cannot read it (the daemon sends no CORS headers): there the same body comes
   * over the WebSocket (the `status` request). */
  async status() {
    if (crossOriginPage(this.url)) {
      const { type, id, ...body } = await this.request({ type: "status" });
      return body;
    }
    const headers = this.token ? { Authorization: `Bearer ${this.token}` } : {};
    const response = await fetchWithTimeout(httpUrl(this.url, "/api/status"), { headers }, this.timeoutMs);
    const body = await response.json();
    if (!response.ok) {
      throw new ThermodeError(body.code ?? "http", body.message ?? `HTTP ${response.status}`, { fromDaemon: true });
    }
    return body;
  }

  /** Send one request (an object with its `type`; the `id` is added) and resolve with its `ok`/`status` reply, or
   * reject with a `ThermodeError` (the daemon's refusal, `timeout`, `connection_closed`). */
  request(message) {
    const socket = this._socket;
    if (socket === null || socket.readyState !== 1) {
      const why = this._closedByUser ? "the client was closed" : "not connected (reconnecting)";
      return Promise.reject(new ThermodeError("connection_closed", why, { request: message.type }));
    }
    const id = this._nextId++;
    const text = JSON.stringify({ ...message, id });
    return new Promise((resolve, reject) => {
      const timer = setTimeout(() => {
        this._waiting.delete(id);
        reject(new ThermodeError("timeout", `no reply to \`${message.type}\` within ${this.timeoutMs} ms`, { requestId: id, request: message.type }));
      }, this.timeoutMs);
      this._waiting.set(id, { resolve, reject, timer, type: message.type });
      this._emit("sent", JSON.parse(text));
      socket.send(text);
    });
  }

  // -- program events -------------------------------------------------------------------------------------------

  /** Waits for the next program event named `event` ("segment_start", "response", "program_end"), on `channel`
   * and at or after `afterTick` when given; earlier events that do not match are passed over. `timeoutMs`: default
   * the client's. Events reach a connection that sent a program or a response, or that subscribes to telemetry. */
  waitForEvent(event, { channel, afterTick, timeoutMs } = {}) {
    const matches = (m) =>
      m.event === event && (channel === undefined || m.channel === channel) && (afterTick === undefined || m.tick >= afterTick);
    while (this._events.length > 0) {
      const next = this._events.shift();
      if (matches(next)) return Promise.resolve(next);
    }
    const waitMs = timeoutMs ?? this.timeoutMs;
    return new Promise((resolve, reject) => {
      const waiter = { matches, resolve, reject };
      waiter.timer = setTimeout(() => {
        this._eventWaiters.delete(waiter);
        reject(new ThermodeError("timeout", `no \`${event}\` event within ${waitMs} ms`));
      }, waitMs);
      this._eventWaiters.add(waiter);
    });
  }

  /** Waits for a participant's response (from any client) on `channel`: the `response` program event. */
  waitForResponse(options = {}) {
    return this.waitForEvent("response", options);
  }

  /** Waits until `channel`'s program has run its last segment (the `program_end` event). */
  waitForProgramEnd(options = {}) {
    return this.waitForEvent("program_end", options);
  }

  // -- listeners ------------------------------------------------------------------------------------------------

  /** Calls `listener` for every `name`: `telemetry` (a frame), `program_event`, `event` (a daemon event such as
   * `recording_failed`), `disconnected` ({code, reason}), `reconnecting` ({attempt, delayMs}), `reconnected`
   * ({attempts}), `reconnect_failed` ({attempts}), `sent` and `received` (every message, parsed). Returns a function
   * that removes the listener. */
  on(name, listener) {
    if (!this._listeners.has(name)) this._listeners.set(name, new Set());
    this._listeners.get(name).add(listener);
    return () => this._listeners.get(name)?.delete(listener);
  }

  /** Whether the connection is open now. */
  get connected() {
    return this._socket !== null && this._socket.readyState === 1;
  }

  /** Closes the connection for good (no reconnection); the daemon releases this client's contacts after its grace
   * period. Resolves once the socket is closed. */
  close() {
    this._closedByUser = true;
    clearTimeout(this._reconnectTimer);
    const socket = this._socket;
    if (socket === null || socket.readyState === 3) return Promise.resolve();
    return new Promise((resolve) => {
      socket.addEventListener("close", () => resolve());
      socket.close();
    });
  }

  // -- connection -----------------------------------------------------------------------------------------------

  async _open() {
    const { Socket, headers } = this._webSocket ?? (await webSocketClass(this.token !== null));
    let address = this.url;
    let socket;
    if (this.token !== null && headers) {
      socket = new Socket(address, { headers: { Authorization: `Bearer ${this.token}` } });
    } else {
      if (this.token !== null) {
        const url = new URL(address);
        url.searchParams.set("token", this.token);
        address = url.toString();
      }
      socket = new Socket(address);
    }
    await new Promise((resolve, reject) => {
      const failed = (event) => reject(new ThermodeError("connection_closed", `cannot open ${this.url}: ${event?.message ?? event?.type ?? "error"}`));
      socket.addEventListener("open", () => {
        socket.removeEventListener("error", failed);
        resolve();
      });
      socket.addEventListener("error", failed);
    });
    this._socket = socket;
    // An error after the opening is followed by `close`, which handles it; without a listener `ws` would throw.
    socket.addEventListener("error", () => {});
    socket.addEventListener("message", (event) => this._receive(event.data));
    socket.addEventListener("close", (event) => this._closed(socket, event));
  }

  _receive(data) {
    let message;
    try {
      message = JSON.parse(typeof data === "string" ? data : data.toString());
    } catch {
      return;
    }
    this._emit("received", message);
    if (message.type === "telemetry") return this._emit("telemetry", message);
    if (message.type === "event") return this._emit("event", message);
    if (message.type === "program_event") return this._programEvent(message);
    const slot = this._waiting.get(message.id);
    if (slot === undefined) return;
    this._waiting.delete(message.id);
    clearTimeout(slot.timer);
    if (message.type === "error") {
      slot.reject(new ThermodeError(message.code, message.message, { fromDaemon: true, requestId: message.id, request: slot.type }));
    } else {
      slot.resolve(message);
    }
  }

  _programEvent(message) {
    this._emit("program_event", message);
    for (const waiter of this._eventWaiters) {
      if (waiter.matches(message)) {
        this._eventWaiters.delete(waiter);
        clearTimeout(waiter.timer);
        waiter.resolve(message);
        return;
      }
    }
    this._events.push(message);
    if (this._events.length > EVENT_BUFFER_LEN) this._events.shift();
  }

  _closed(socket, event) {
    if (socket !== this._socket) return;
    this._socket = null;
    for (const [id, slot] of this._waiting) {
      clearTimeout(slot.timer);
      slot.reject(new ThermodeError("connection_closed", `closed (${event.code}) before the reply`, { requestId: id, request: slot.type }));
    }
    this._waiting.clear();
    if (this._closedByUser) return;
    this._emit("disconnected", { code: event.code, reason: String(event.reason ?? "") });
    if (this.reconnectPolicy !== null) this._scheduleReconnect(1);
  }

  _scheduleReconnect(attempt) {
    const policy = this.reconnectPolicy;
    if (attempt > policy.maxAttempts) {
      this._emit("reconnect_failed", { attempts: attempt - 1 });
      return;
    }
    const delayMs = backoffDelayMs(policy, attempt);
    this._emit("reconnecting", { attempt, delayMs });
    this._reconnectTimer = setTimeout(async () => {
      if (this._closedByUser) return;
      try {
        await this._open();
      } catch {
        return this._scheduleReconnect(attempt + 1);
      }
      if (this._closedByUser) return this._socket?.close();
      if (this._subscribedHz !== null) await this.subscribe(this._subscribedHz).catch(() => {});
      this._emit("reconnected", { attempts: attempt });
    }, delayMs);
  }

  _emit(name, value) {
    for (const listener of this._listeners.get(name) ?? []) {
      try {
        listener(value);
      } catch (error) {
        queueMicrotask(() => {
          throw error;
        });
      }
    }
  }
}

/** Whether this runs in a browser page whose origin is not the daemon's (of the WebSocket address `wsUrl`). */
function crossOriginPage(wsUrl) {
  const origin = globalThis.location?.origin;
  if (typeof origin !== "string" || (typeof process !== "undefined" && process.versions?.node != null)) return false;
  return new URL(httpUrl(wsUrl, "/")).origin !== origin;
}

/** `fetch` that gives up after `timeoutMs` with a `timeout` error. */
async function fetchWithTimeout(url, init, timeoutMs) {
  const controller = new AbortController();
  const timer = setTimeout(() => controller.abort(), timeoutMs);
  try {
    return await fetch(url, { ...init, signal: controller.signal });
  } catch (error) {
    const code = controller.signal.aborted ? "timeout" : "http";
    throw new ThermodeError(code, `GET ${url}: ${error.message ?? error}`);
  } finally {
    clearTimeout(timer);
  }
}

/** Opens a connection: `await connect("ws://127.0.0.1:8765/api/ws", { token })`. */
export function connect(url, options = {}) {
  return Client.connect(url, options);
}
