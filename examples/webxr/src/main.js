// The example scene: an aluminium cube and a wooden block on a table, both at room temperature, and a pine-like
// custom material given by its k, ρ, c; the right index tip drives display channel 1 (the simulated display's index
// finger), the left index tip channel 0. `window.thermalApp` exposes the scene to tests (and the console).

import * as THREE from "three";
import { connect } from "thermode-client";
import { ThermalContacts, ThermalFinger, ThermalMaterial } from "./thermal.js";

const params = new URLSearchParams(location.search);
const daemonUrl = params.get("daemon") ?? "ws://127.0.0.1:8765/api/ws";
const log = document.getElementById("log");

/** With `?emulate=1`: an emulated headset with tracked hands (iwer) replaces the browser's WebXR. */
async function emulatedDevice() {
  if (params.get("emulate") !== "1") return null;
  const { XRDevice, metaQuest3 } = await import("iwer");
  const device = new XRDevice(metaQuest3);
  device.installRuntime({ forceInstall: true });
  device.primaryInputMode = "hand";
  return device;
}

/** The scene's objects: each thermal mesh with its ThermalMaterial. */
function buildScene(scene) {
  scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 3));
  const aluminium = new THREE.Mesh(new THREE.BoxGeometry(0.1, 0.1, 0.1), new THREE.MeshStandardMaterial({ color: 0xb0b4b8, metalness: 0.9 }));
  aluminium.position.set(0, 1.0, -0.4);
  aluminium.name = "aluminium cube";
  ThermalMaterial.attach(aluminium, new ThermalMaterial({ name: "aluminium" }));
  const wood = new THREE.Mesh(new THREE.BoxGeometry(0.2, 0.05, 0.1), new THREE.MeshStandardMaterial({ color: 0x9a6b3f }));
  wood.position.set(0.25, 1.0, -0.4);
  wood.name = "wooden block";
  ThermalMaterial.attach(wood, new ThermalMaterial({ name: "wood" }));
  const pine = new THREE.Mesh(new THREE.BoxGeometry(0.1, 0.05, 0.1), new THREE.MeshStandardMaterial({ color: 0xd9b380 }));
  pine.position.set(-0.25, 1.0, -0.4);
  pine.name = "warm pine board";
  // A custom material by its properties: pine, k 0.12 W/(m·K), ρ 500 kg/m³, c 1600 J/(kg·K), 2 cm, at 30 °C.
  ThermalMaterial.attach(pine, new ThermalMaterial({ name: "pine", k: 0.12, rho: 500, c: 1600, thicknessM: 0.02, objectTempC: 30 }));
  scene.add(aluminium, wood, pine);
  return { aluminium, wood, pine };
}

async function main() {
  const device = await emulatedDevice();
  const client = await connect(daemonUrl, { token: params.get("token") ?? undefined });
  const renderer = new THREE.WebGLRenderer({ antialias: false });
  renderer.setSize(640, 480);
  renderer.xr.enabled = true;
  renderer.xr.setReferenceSpaceType("local-floor");
  document.body.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(70, 640 / 480, 0.01, 20);
  camera.position.set(0, 1.6, 0);
  const meshes = buildScene(scene);
  const contacts = new ThermalContacts(client);
  contacts.addFinger(new ThermalFinger({ handedness: "left", channel: 0 }));
  contacts.addFinger(new ThermalFinger({ handedness: "right", channel: 1 }));
  contacts.addMeshes(scene);
  contacts.on((e) => {
    if (e.kind !== "applied" && e.kind !== "error") return;
    log.textContent = `channel ${e.channel}: ${e.mesh?.name ?? "air"}${e.error ? ` (${e.error.message})` : ""}`;
  });
  renderer.setAnimationLoop((time, frame) => {
    if (frame) contacts.update(frame, renderer.xr.getReferenceSpace());
    renderer.render(scene, camera);
  });
  log.textContent = "connected: enter VR";
  window.thermalApp = { THREE, client, contacts, device, meshes, renderer, enterXR: () => enterXR(renderer) };
  if (device === null) addEnterButton(renderer);
}

/** Starts an immersive session with hand tracking. */
async function enterXR(renderer) {
  const session = await navigator.xr.requestSession("immersive-vr", { optionalFeatures: ["local-floor", "hand-tracking"] });
  await renderer.xr.setSession(session);
  return session;
}

function addEnterButton(renderer) {
  const button = document.createElement("button");
  button.textContent = "Enter VR";
  button.style.cssText = "position:absolute;bottom:16px;left:16px;font-size:20px";
  button.onclick = () => enterXR(renderer).catch((error) => (log.textContent = String(error)));
  document.body.appendChild(button);
}

main().catch((error) => {
  log.textContent = `failed: ${error.message ?? error}`;
  window.thermalAppError = String(error?.stack ?? error);
});
