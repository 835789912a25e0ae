// lgi view: plays a solved take streamed from the lgi server in chunks of frames.
// State for tests and for the report's links: document.body.dataset.frame is the time code on
// screen once its frame's data is drawn; location.hash "#frame=N" (a time code) seeks.
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";

const $ = (id) => document.getElementById(id);
const status = (text) => { $("status").textContent = text; };

async function fetchBytes(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: ${r.status} ${await r.text()}`);
  return r.arrayBuffer();
}

// Viridis and magma endpoints sampled at 5 stops (enough for a legend-read colour scale).
const VIRIDIS = [[0.267, 0.005, 0.329], [0.229, 0.322, 0.546], [0.128, 0.567, 0.551],
                 [0.369, 0.789, 0.383], [0.993, 0.906, 0.144]];
const MAGMA = [[0.001, 0.000, 0.014], [0.316, 0.071, 0.485], [0.716, 0.215, 0.475],
               [0.987, 0.535, 0.383], [0.987, 0.991, 0.750]];
function ramp(stops, t) {
  const x = Math.min(Math.max(t, 0), 1) * (stops.length - 1);
  const i = Math.min(Math.floor(x), stops.length - 2);
  const f = x - i;
  return stops[i].map((a, k) => a + (stops[i + 1][k] - a) * f);
}

function percentile(values, p) {
  const v = values.filter(Number.isFinite).sort((a, b) => a - b);
  if (!v.length) return 0;
  return v[Math.min(v.length - 1, Math.floor(p * (v.length - 1)))];
}

const meta = await (await fetch("meta.json")).json();
const F = meta.frames, B = meta.markers.length, V = meta.vertices, CHUNK = meta.chunk;
const unit = meta.units ? ` ${meta.units}` : "";
document.title = `lgi view: ${meta.source}`;
$("title").textContent = meta.source;
$("slider").max = String(F - 1);
if (meta.reference) {
  const o = document.createElement("option");
  o.value = "difference";
  o.textContent = `difference to ${meta.reference}`;
  $("colour").append(o);
}
if (!meta.has_markers) {
  $("show-markers").checked = false;
  $("show-markers").disabled = true;
  $("show-markers").parentElement.title = "the solved file holds no marker positions";
}

const [triBytes, resBytes] = await Promise.all([
  fetchBytes("triangles.bin"), fetchBytes("residuals.bin")]);
const residuals = new Float32Array(resBytes);  // (F, B), NaN missing
const resTop = Math.max(percentile(Array.from(residuals), 0.99), 1e-12);

// Chunks: positions, markers and colours by chunk start, the most recent kept.
const chunks = new Map();
const KEEP = 12;
function chunkOf(frame) { return frame - (frame % CHUNK); }
function loadChunk(start) {
  if (chunks.has(start)) return chunks.get(start).ready;
  const entry = { colours: new Map() };
  entry.ready = (async () => {
    const [p, m] = await Promise.all([
      fetchBytes(`positions.bin?start=${start}`),
      meta.has_markers ? fetchBytes(`markers.bin?start=${start}`) : null]);
    entry.positions = new Float32Array(p);
    entry.markers = m ? new Float32Array(m) : null;
    return entry;
  })();
  chunks.set(start, entry);
  while (chunks.size > KEEP) chunks.delete(chunks.keys().next().value);
  return entry.ready;
}
async function loadColours(start, mode) {
  const entry = await loadChunk(start);
  if (!entry.colours.has(mode)) {
    entry.colours.set(mode, fetchBytes(`colours.bin?mode=${mode}&start=${start}`)
      .then((b) => new Float32Array(b)));
  }
  return entry.colours.get(mode);
}

// Scene.
const stage = $("stage");
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
stage.prepend(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf4f4f4);
scene.add(new THREE.HemisphereLight(0xffffff, 0x666666, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(30, 1, 0.01, 1e6);
scene.add(camera);
camera.add(sun);
sun.position.set(0.3, 0.5, 1);

const geometry = new THREE.BufferGeometry();
geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(triBytes), 1));
const position = new THREE.BufferAttribute(new Float32Array(V * 3), 3);
position.setUsage(THREE.DynamicDrawUsage);
geometry.setAttribute("position", position);
const colour = new THREE.BufferAttribute(new Float32Array(V * 3).fill(0.8), 3);
colour.setUsage(THREE.DynamicDrawUsage);
geometry.setAttribute("color", colour);
const material = new THREE.MeshStandardMaterial({
  vertexColors: true, roughness: 0.7, metalness: 0.0, side: THREE.DoubleSide });
const mesh = new THREE.Mesh(geometry, material);
mesh.frustumCulled = false;
scene.add(mesh);

let markerMesh = null;
const controls = new OrbitControls(camera, renderer.domElement);

function resize() {
  const w = stage.clientWidth, h = stage.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
new ResizeObserver(() => { resize(); draw(); }).observe(stage);

function frameCamera() {
  geometry.computeBoundingSphere();
  const s = geometry.boundingSphere;
  // Close enough that the face fills most of the view (the sphere bounds its corners).
  const d = s.radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * 0.8;
  camera.position.set(s.center.x, s.center.y, s.center.z + d);
  camera.near = d / 100;
  camera.far = d * 100;
  camera.updateProjectionMatrix();
  controls.target.copy(s.center);
  controls.update();
  const r = s.radius * 0.012;
  markerMesh = new THREE.InstancedMesh(
    new THREE.SphereGeometry(r, 12, 8), new THREE.MeshBasicMaterial(), B);
  markerMesh.frustumCulled = false;
  scene.add(markerMesh);
}

// What is on screen.
let shown = -1, wanted = 0, playing = false, mode = "none", colourTop = 1;
const dummy = new THREE.Object3D();
const tint = new THREE.Color();

async function show(frame) {
  frame = Math.min(Math.max(Math.round(frame), 0), F - 1);
  wanted = frame;
  const start = chunkOf(frame);
  const entry = await loadChunk(start);
  const values = mode === "none" ? null : await loadColours(start, mode);
  if (wanted !== frame) return;  // a later seek won
  const k = frame - start;
  position.array.set(entry.positions.subarray(k * V * 3, (k + 1) * V * 3));
  position.needsUpdate = true;
  geometry.computeVertexNormals();
  if (values) {
    const row = values.subarray(k * V, (k + 1) * V);
    for (let i = 0; i < V; i++) {
      const c = ramp(VIRIDIS, row[i] / colourTop);
      colour.array[3 * i] = c[0]; colour.array[3 * i + 1] = c[1]; colour.array[3 * i + 2] = c[2];
    }
  } else {
    colour.array.fill(0.8);
  }
  colour.needsUpdate = true;
  if (shown < 0) frameCamera();
  if (markerMesh) {
    const on = $("show-markers").checked && entry.markers;
    for (let b = 0; b < B; b++) {
      const o = (k * B + b) * 3;
      const r = residuals[frame * B + b];
      const present = on && Number.isFinite(entry.markers[o]);
      dummy.position.set(present ? entry.markers[o] : 0, present ? entry.markers[o + 1] : 0,
                         present ? entry.markers[o + 2] : 0);
      dummy.scale.setScalar(present ? 1 : 0);
      dummy.updateMatrix();
      markerMesh.setMatrixAt(b, dummy.matrix);
      const c = repairedAt[frame * B + b] ? REPAIRED
        : ramp(MAGMA, Number.isFinite(r) ? 0.15 + 0.85 * r / resTop : 0);
      markerMesh.setColorAt(b, tint.setRGB(c[0], c[1], c[2]));
    }
    markerMesh.instanceMatrix.needsUpdate = true;
    if (markerMesh.instanceColor) markerMesh.instanceColor.needsUpdate = true;
  }
  shown = frame;
  $("slider").value = String(frame);
  $("frame-label").textContent = `time code ${meta.start + frame} (${frame + 1}/${F})`;
  $("cursor").style.left = `${(frame + 0.5) / F * 100}%`;
  draw();
  document.body.dataset.frame = String(meta.start + frame);
  // Stream ahead: the next chunk is on its way before playback reaches it.
  if (start + CHUNK < F) loadChunk(start + CHUNK);
}

function draw() { renderer.render(scene, camera); }
controls.addEventListener("change", draw);

async function setMode(m) {
  mode = m;
  if (mode !== "none") {
    // One colour scale for the take: the 99th percentile of the first chunk's values.
    const v = await loadColours(chunkOf(shown < 0 ? 0 : shown), mode);
    colourTop = Math.max(percentile(Array.from(v), 0.99), 1e-12);
    $("legend").textContent = `${$("colour").selectedOptions[0].textContent}: ` +
      `0 to ${colourTop.toPrecision(3)}${unit} (viridis)`;
  } else {
    $("legend").textContent = `marker colour: residual 0 to ${resTop.toPrecision(3)}${unit}`;
  }
  document.body.dataset.colour = mode;
  await show(shown < 0 ? 0 : shown);
}

// Heatmap: one pixel per (frame, marker).
function drawHeatmap() {
  const c = $("heatmap");
  c.width = F; c.height = B;
  const ctx = c.getContext("2d");
  const img = ctx.createImageData(F, B);
  for (let f = 0; f < F; f++) {
    for (let b = 0; b < B; b++) {
      const r = residuals[f * B + b];
      const rgb = Number.isFinite(r) ? ramp(MAGMA, r / resTop) : [0.6, 0.6, 0.6];
      const o = (b * F + f) * 4;
      img.data[o] = rgb[0] * 255; img.data[o + 1] = rgb[1] * 255; img.data[o + 2] = rgb[2] * 255;
      img.data[o + 3] = 255;
    }
  }
  ctx.putImageData(img, 0, 0);
  c.addEventListener("click", (e) => {
    const box = c.getBoundingClientRect();
    const f = Math.floor((e.clientX - box.left) / box.width * F);
    const b = Math.floor((e.clientY - box.top) / box.height * B);
    status(`${meta.markers[Math.min(b, B - 1)]}`);
    seek(f);
  });
}

// Samples repaired before the solve (a swap undone, a spike solved as missing): drawn cyan.
const REPAIRED = [0.0, 0.8, 1.0];
const repairedAt = new Uint8Array(F * B);
for (const r of meta.repairs) {
  for (const name of r.markers) {
    const b = meta.markers.indexOf(name);
    for (let f = r.first; f <= r.last && b >= 0; f++) repairedAt[f * B + b] = 1;
  }
}

function listRepaired() {
  if (!meta.repairs.length) return;
  $("repaired-box").hidden = false;
  for (const r of meta.repairs) {
    const li = document.createElement("li");
    const btn = document.createElement("button");
    btn.type = "button";
    btn.dataset.frame = String(meta.start + r.first);
    btn.textContent = r.line;
    btn.addEventListener("click", () => seek(r.first));
    li.append(btn);
    $("repaired").append(li);
  }
}

function listWorst() {
  for (const w of meta.worst_frames) {
    const li = document.createElement("li");
    const btn = document.createElement("button");
    btn.type = "button";
    btn.dataset.frame = String(meta.start + w.frame);
    btn.textContent = `time code ${meta.start + w.frame}: ${w.residual.toPrecision(3)}${unit}` +
      ` (${w.marker})`;
    btn.addEventListener("click", () => seek(w.frame));
    li.append(btn);
    $("worst").append(li);
  }
}

function seek(frame) { playing = false; $("play").textContent = "Play"; show(frame); }

function fromHash() {
  const m = /frame=(-?\d+)/.exec(location.hash);
  if (m) seek(Number(m[1]) - meta.start);
}

// Playback at the take's rate: frames are skipped, not slowed, when drawing falls behind.
let clock = 0, origin = 0;
function tick(t) {
  if (playing) {
    const target = origin + Math.floor((t - clock) / 1000 * meta.fps);
    if (target >= F) { playing = false; $("play").textContent = "Play"; }
    else if (target !== wanted) show(target);
  }
  requestAnimationFrame(tick);
}
$("play").addEventListener("click", () => {
  playing = !playing;
  $("play").textContent = playing ? "Pause" : "Play";
  if (playing) { clock = performance.now(); origin = shown >= F - 1 ? 0 : shown; }
});
$("slider").addEventListener("input", (e) => seek(Number(e.target.value)));
$("colour").addEventListener("change", (e) => setMode(e.target.value));
$("show-markers").addEventListener("change", () => show(shown));
window.addEventListener("hashchange", fromHash);

resize();
drawHeatmap();
listWorst();
listRepaired();
await setMode("none");
if (!meta.fps_known) status("the take has no frame rate: playing at 24 fps");
fromHash();
document.body.dataset.ready = "1";
requestAnimationFrame(tick);
