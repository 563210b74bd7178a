// Thermal touch for three.js WebXR scenes, over thermode's contact API (docs/api.md) with the thermode-client
// package:
// - `ThermalMaterial`: what a mesh is made of for the finger (a library material, or k, ρ, c and thickness) and its
//   temperature; attach it with `ThermalMaterial.attach(mesh, material)`.
// - `ThermalFinger`: a joint of a WebXR hand (by default the index finger's tip) mapped to a display channel.
// - `ThermalContacts`: once per rendered frame, finds which thermal mesh each finger touches and sends events to the
//   daemon: a `touch` when a finger enters a mesh, a `release` when it leaves — never a per-frame stream. One request
//   per channel is in flight at a time and the newest state wins (a finger that flickers in and out at frame rate
//   ends in the state it is in), paced below the daemon's per-connection rate cap.

import { Box3, Vector3 } from "three";

/** The key of a mesh's thermal material in `mesh.userData`. */
const USER_DATA_KEY = "thermodeMaterial";

/** Requests per second ThermalContacts sends at most (the daemon allows 50/s sustained, burst 100). Default 40. */
export const DEFAULT_MAX_REQUESTS_PER_S = 40;

/** What an object is made of, as the finger feels it. */
export class ThermalMaterial {
  /** `spec`: `{name}` for a library material (`GET /api/materials`: "aluminium", "wood", …) or `{k, rho, c,
   * thicknessM, name}` — conductivity k [W/(m·K)], density ρ [kg/m³], specific heat c [J/(kg·K)], thickness [m]
   * (default 0.01), an optional label; `objectTempC`: the object's temperature [°C] (default: the daemon's room
   * temperature, 23). */
  constructor(spec) {
    const { name, k, rho, c, thicknessM, objectTempC } = spec;
    if (k === undefined && typeof name !== "string") throw new TypeError("ThermalMaterial needs a library `name` or k, rho and c");
    if (k !== undefined && [k, rho, c].some((v) => typeof v !== "number" || !Number.isFinite(v))) {
      throw new TypeError("ThermalMaterial: k, rho and c must be finite numbers (W/(m·K), kg/m³, J/(kg·K))");
    }
    this.name = name ?? null;
    this.properties = k === undefined ? null : { k, rho, c, thicknessM: thicknessM ?? null };
    this.objectTempC = objectTempC ?? null;
  }

  /** The daemon's `material` (a name) or `properties` (an object of SI values) for a `touch`. */
  touchMaterial() {
    if (this.properties === null) return this.name;
    const { k, rho, c, thicknessM } = this.properties;
    const properties = { conductivity_w_mk: k, density_kg_m3: rho, specific_heat_j_kgk: c };
    if (thicknessM !== null) properties.thickness_m = thicknessM;
    if (this.name !== null) properties.name = this.name;
    return properties;
  }

  /** Marks `mesh` as made of `material`; returns the mesh. */
  static attach(mesh, material) {
    mesh.userData[USER_DATA_KEY] = material;
    return mesh;
  }

  /** The thermal material of `mesh`, or null. */
  static of(mesh) {
    return mesh.userData[USER_DATA_KEY] ?? null;
  }
}

/** A hand joint that feels: `handedness` "left" or "right", `channel` the display channel it drives, `joint` the
 * WebXR hand joint (default "index-finger-tip"), `releaseMarginM` the extra distance [m] the joint must leave a mesh
 * by before the contact ends (default 0.002: no chatter at the surface). */
export class ThermalFinger {
  constructor({ handedness, channel, joint = "index-finger-tip", releaseMarginM = 0.002 }) {
    if (handedness !== "left" && handedness !== "right") throw new TypeError("ThermalFinger: handedness is left or right");
    if (!Number.isInteger(channel) || channel < 0) throw new TypeError("ThermalFinger: channel is a display channel (0, 1, …)");
    this.handedness = handedness;
    this.channel = channel;
    this.joint = joint;
    this.releaseMarginM = releaseMarginM;
    /** The joint's last position in the reference space [m], or null before the hand was seen. */
    this.position = null;
    /** The joint's radius [m] (from the hand tracking). */
    this.radiusM = 0.008;
    /** The mesh touched now, or null. */
    this.touching = null;
  }

  /** Reads the joint's pose from `frame` in `referenceSpace`; false when the hand is not tracked this frame. */
  track(frame, referenceSpace) {
    for (const source of frame.session.inputSources) {
      if (source.hand == null || source.handedness !== this.handedness) continue;
      const space = source.hand.get(this.joint);
      const pose = space ? frame.getJointPose(space, referenceSpace) : null;
      if (pose == null) return false;
      const p = pose.transform.position;
      this.position = new Vector3(p.x, p.y, p.z);
      this.radiusM = pose.radius ?? this.radiusM;
      return true;
    }
    return false;
  }

  /** The mesh of `meshes` this finger touches: the one it touched while still within the release margin, else the
   * nearest one its joint sphere reaches (the mesh's world bounding box), else null. */
  contactAmong(meshes) {
    if (this.position === null) return null;
    const box = new Box3();
    const distance = (mesh) => box.setFromObject(mesh).distanceToPoint(this.position);
    if (this.touching !== null && meshes.includes(this.touching) && distance(this.touching) <= this.radiusM + this.releaseMarginM) {
      return this.touching;
    }
    let nearest = null;
    let nearestM = Infinity;
    for (const mesh of meshes) {
      const d = distance(mesh);
      if (d <= this.radiusM && d < nearestM) [nearest, nearestM] = [mesh, d];
    }
    return nearest;
  }
}

/** Turns the contacts of fingers with thermal meshes into `touch`/`release` requests on a thermode client. */
export class ThermalContacts {
  /** `client`: a connected thermode-client `Client`; `maxRequestsPerS`: the pace (default 40/s, burst as many). */
  constructor(client, { maxRequestsPerS = DEFAULT_MAX_REQUESTS_PER_S } = {}) {
    this.client = client;
    this.fingers = [];
    this.meshes = [];
    /** Rendered frames seen by `update`. */
    this.frame = 0;
    this.stats = { touches: 0, releases: 0, errors: 0, throttled: 0 };
    this._channels = new Map();
    this._listeners = new Set();
    this._bucket = { tokens: maxRequestsPerS, capacity: maxRequestsPerS, perMs: maxRequestsPerS / 1000, at: now() };
    this._retry = null;
    // After a reconnection the daemon releases the old connection's contacts: touch again what is still touched.
    client.on("reconnected", () => {
      for (const state of this._channels.values()) state.applied = null;
      this._flush();
    });
  }

  /** Adds a finger (a `ThermalFinger`); returns it. */
  addFinger(finger) {
    this.fingers.push(finger);
    this._channels.set(finger.channel, { applied: null, inFlight: false, desired: null });
    return finger;
  }

  /** Adds every mesh under `root` that has a `ThermalMaterial`. */
  addMeshes(root) {
    root.traverse((object) => {
      if (ThermalMaterial.of(object) !== null && !this.meshes.includes(object)) this.meshes.push(object);
    });
  }

  /** Calls `listener({kind, channel, mesh, frame, reply?, error?})` for each `enter`, `exit`, `applied` and
   * `error`; returns a function that removes it. */
  on(listener) {
    this._listeners.add(listener);
    return () => this._listeners.delete(listener);
  }

  /** Once per rendered frame, with the frame's XRFrame and the scene's reference space. */
  update(frame, referenceSpace) {
    this.frame += 1;
    for (const finger of this.fingers) {
      if (!finger.track(frame, referenceSpace)) continue;
      const mesh = finger.contactAmong(this.meshes);
      if (mesh === finger.touching) continue;
      if (finger.touching !== null) this._say({ kind: "exit", channel: finger.channel, mesh: finger.touching });
      finger.touching = mesh;
      if (mesh !== null) this._say({ kind: "enter", channel: finger.channel, mesh });
      this._channels.get(finger.channel).desired = mesh;
    }
    this._flush();
  }

  /** Whether every channel's daemon state is what its finger touches, with nothing in flight. */
  get settled() {
    return [...this._channels.values()].every((s) => !s.inFlight && s.applied === s.desired);
  }

  /** Sends, for each channel whose applied state differs from its finger's, the one request that makes it so. */
  _flush() {
    for (const [channel, state] of this._channels) {
      if (state.inFlight || state.applied === state.desired || !this.client.connected) continue;
      if (!this._take()) return this._retryLater(1000 / (this._bucket.perMs * 1000));
      this._send(channel, state, state.desired);
    }
  }

  _send(channel, state, mesh) {
    state.inFlight = true;
    const material = mesh === null ? null : ThermalMaterial.of(mesh);
    const request =
      material === null ? this.client.release(channel) : this.client.touch(channel, material.touchMaterial(), material.objectTempC ?? undefined);
    this.stats[material === null ? "releases" : "touches"] += 1;
    request.then(
      (reply) => {
        state.inFlight = false;
        state.applied = mesh;
        this._say({ kind: "applied", channel, mesh, reply });
        this._flush();
      },
      (error) => {
        state.inFlight = false;
        this.stats.errors += 1;
        this._say({ kind: "error", channel, mesh, error });
        // A refusal the next try can overcome (rate, load, a stop_all's cancellation, a reconnection) is retried;
        // any other (an unknown material, a fault) stands until the finger's contact changes.
        const transient = ["rate_limited", "busy", "cancelled", "connection_closed", "timeout"].includes(error.code);
        if (transient) this._retryLater(100);
        else state.applied = mesh;
      },
    );
  }

  /** Takes a request token from the pacing bucket; false when it is empty. */
  _take() {
    const bucket = this._bucket;
    const t = now();
    bucket.tokens = Math.min(bucket.capacity, bucket.tokens + (t - bucket.at) * bucket.perMs);
    bucket.at = t;
    if (bucket.tokens < 1) {
      this.stats.throttled += 1;
      return false;
    }
    bucket.tokens -= 1;
    return true;
  }

  _retryLater(ms) {
    if (this._retry !== null) return;
    this._retry = setTimeout(() => {
      this._retry = null;
      this._flush();
    }, ms);
  }

  _say(event) {
    const full = { ...event, frame: this.frame };
    for (const listener of this._listeners) listener(full);
  }
}

function now() {
  return typeof performance !== "undefined" ? performance.now() : Date.now();
}
