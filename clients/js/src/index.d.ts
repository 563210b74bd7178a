// Type declarations of the thermode JavaScript client (hand-written; the wire format is docs/protocol.schema.json,
// generated from the daemon's serde types, and docs/api.md).

/** The daemon's stable error codes (docs/api.md "Error codes"). */
export type DaemonErrorCode =
  | "bad_json"
  | "unknown_type"
  | "missing_field"
  | "unknown_field"
  | "bad_value"
  | "unknown_channel"
  | "unknown_material"
  | "too_large"
  | "rate_limited"
  | "unauthorized"
  | "forbidden"
  | "device_fault"
  | "busy"
  | "too_many_connections"
  | "cancelled"
  | "recording_failed"
  | "dose_not_recorded"
  | "dose_budget_spent";

/** The client's own failures: no reply in time, the connection closed, an HTTP request that failed. */
export type ClientErrorCode = "timeout" | "connection_closed" | "http";

/** Milliseconds a request waits for its reply (default 5000). */
export declare const DEFAULT_TIMEOUT_MS: number;
/** Most segments of one channel's program (999). */
export declare const MAX_SEGMENTS: number;

/** A reconnection policy: waits of initialDelayMs × factor^(attempt−1), at most maxDelayMs, for maxAttempts. */
export interface ReconnectPolicy {
  /** First wait [ms]; default 250. */
  initialDelayMs: number;
  /** Growth per attempt; default 2. */
  factor: number;
  /** Longest wait [ms]; default 10000. */
  maxDelayMs: number;
  /** Attempts before giving up (`reconnect_failed`); default Infinity. */
  maxAttempts: number;
}
export declare const DEFAULT_RECONNECT: Readonly<ReconnectPolicy>;

/** The wait [ms] before reconnection attempt `attempt` (from 1). */
export declare function backoffDelayMs(policy: ReconnectPolicy, attempt: number): number;
/** The HTTP address of `path` on the daemon of the WebSocket address `wsUrl`. */
export declare function httpUrl(wsUrl: string, path: string): string;

/** A refused request (`fromDaemon`: the daemon's error reply, nothing changed) or a failure of the client. */
export declare class ThermodeError extends Error {
  readonly code: DaemonErrorCode | ClientErrorCode;
  /** The explanation (the daemon's `message`). */
  readonly detail: string;
  readonly fromDaemon: boolean;
  readonly requestId: number | null;
  /** The request's `type`. */
  readonly request: string | null;
}

export interface ClientOptions {
  /** The daemon's `--token`; default none. */
  token?: string;
  /** Reply wait [ms]; default 5000. */
  timeoutMs?: number;
  /** `false`: no reconnection; else a (partial) policy; default `DEFAULT_RECONNECT`. */
  reconnect?: false | Partial<ReconnectPolicy>;
  /** A WebSocket constructor to use instead of the platform's (browser: the global one; Node: `ws` when installed,
   * else the global one, else the package's own). */
  WebSocket?: new (url: string, options?: { headers?: Record<string, string> }) => unknown;
  /** Whether `WebSocket` takes `{headers}` (then a token goes in a header, else in the address); default false. */
  webSocketTakesHeaders?: boolean;
}

/** A material by its SI properties (each within docs/ranges.md). */
export interface MaterialProperties {
  /** Thermal conductivity k [W/(m·K)], 0.01–2500. */
  conductivity_w_mk: number;
  /** Density ρ [kg/m³], 1–25000. */
  density_kg_m3: number;
  /** Specific heat c [J/(kg·K)], 100–15000. */
  specific_heat_j_kgk: number;
  /** Thickness [m], 0.0001–1; default 0.01. */
  thickness_m?: number;
  /** A label (1–64 of A–Z a–z 0–9 _ - .); default `custom`. */
  name?: string;
}

/** A program segment: a ramp `{to_c, rate_c_s}`, a step `{to_c}` or a hold `{hold_s}`; ramps and holds may end at a
 * response (`until: "response"`). Temperatures [°C], rates [°C/s], durations [s]. */
export type Segment =
  | { to_c: number; rate_c_s: number; until?: "response" }
  | { to_c: number }
  | { hold_s: number; until?: "response" };

/** A successful reply (`type` "ok"), with the request's own fields (`tick`, `time_s`, …). */
export interface OkReply {
  type: "ok";
  id: number | string;
  request: string;
  tick?: number;
  time_s?: number;
  [field: string]: unknown;
}

/** One channel of a telemetry frame (the `render` CSV's names; null where the device cannot measure). */
export interface ChannelTelemetry {
  channel: number;
  contact: boolean;
  material: string | null;
  mode: "air" | "touch" | "direct";
  target_skin_c: number | null;
  skin_c: number | null;
  display_setpoint_c: number | null;
  sensor_c: number | null;
  plate_estimate_c: number | null;
  finger_c?: number | null;
  current_a: number | null;
  hot_side_c: number | null;
  fault: number;
  cem43_min: number;
  time_at_or_above_43_s: number;
  dose_lockout: boolean;
}

export interface Telemetry {
  type: "telemetry";
  time_s: number;
  tick: number;
  channels: ChannelTelemetry[];
}

export interface ProgramEvent {
  type: "program_event";
  event: "segment_start" | "response" | "program_end";
  channel: number;
  tick: number;
  time_s: number;
  segment?: number;
  to_c?: number;
  cutoff_c?: number;
  kind?: "button" | "rating";
  value?: number | null;
  setpoint_c: number | null;
  sensor_c: number | null;
}

export interface DaemonEvent {
  type: "event";
  event: string;
  [field: string]: unknown;
}

/** The body of `GET /api/status` (docs/api.md "HTTP"; `#/$defs/Status` of the schema). */
export interface Status {
  version: string;
  device: string;
  running: boolean;
  time_s: number;
  tick: number;
  channel_count: number;
  channels: Array<Record<string, unknown> & { channel: number; contact: boolean; material: string | null; mode: string }>;
  contacts: Array<{ channel: number; material: string | null; mode: string; owner: Record<string, unknown> }>;
  limits: Record<string, number>;
  [field: string]: unknown;
}

export interface ClientEvents {
  telemetry: Telemetry;
  program_event: ProgramEvent;
  event: DaemonEvent;
  disconnected: { code: number; reason: string };
  reconnecting: { attempt: number; delayMs: number };
  reconnected: { attempts: number };
  reconnect_failed: { attempts: number };
  sent: Record<string, unknown>;
  received: Record<string, unknown>;
}

export interface WaitOptions {
  channel?: number;
  afterTick?: number;
  /** Longest wait [ms]; default the client's `timeoutMs`. */
  timeoutMs?: number;
}

export declare class Client {
  static connect(url: string, options?: ClientOptions): Promise<Client>;
  readonly url: string;
  readonly connected: boolean;
  touch(channel: number, material: string | MaterialProperties, objectTempC?: number): Promise<OkReply>;
  release(channel: number): Promise<OkReply>;
  setpoint(channel: number, tempC: number, rateCPerS: number): Promise<OkReply>;
  clearFault(channel: number): Promise<OkReply>;
  stopAll(): Promise<OkReply>;
  marker(text: string, channel?: number): Promise<OkReply>;
  program(channels: Record<number | string, Segment[]> | Map<number, Segment[]>): Promise<OkReply>;
  programStop(channel: number): Promise<OkReply>;
  response(channel: number, kind?: "button" | "rating", value?: number): Promise<OkReply>;
  subscribe(rateHz: number): Promise<OkReply>;
  unsubscribe(): Promise<OkReply>;
  status(): Promise<Status>;
  request(message: { type: string; [field: string]: unknown }): Promise<OkReply | ({ type: "status" } & Status)>;
  waitForEvent(event: ProgramEvent["event"], options?: WaitOptions): Promise<ProgramEvent>;
  waitForResponse(options?: WaitOptions): Promise<ProgramEvent>;
  waitForProgramEnd(options?: WaitOptions): Promise<ProgramEvent>;
  on<K extends keyof ClientEvents>(name: K, listener: (value: ClientEvents[K]) => void): () => void;
  close(): Promise<void>;
}

/** `Client.connect(url, options)`. */
export declare function connect(url: string, options?: ClientOptions): Promise<Client>;
