// The hdov viewer: a walk through one database served by `hdov serve`.
//
// On each cell flip it asks /query what is visible from the camera's cell (the whole cell's
// answer, so turning the head needs no request; three.js culls to the frustum), loads the meshes
// the answer names, and drops what the new answer lacks. Meshes are kept by URL: a mesh is one
// stored LOD record, immutable, shared by every instance, and the server's ETags turn a reload
// into a 304.
//
// URL parameters: at=X,Y,Z and look=DX,DY,DZ (a fixed start), walk=straight|turning|back-and-forth
// and steps=N (follow a recorded walk), colour=shading|dov|lod, hud=0 (no overlay: a clean
// picture), eta, mode, lod_rule (passed to /query).
//
// "draw" (the menu, or draw=tiles|tiles-alone in the URL) hands the walk, where it stands, to the
// 3D Tiles page (/tiles.html): the same database as a tileset in 3DTilesRendererJS, with hdov's
// visibility plugin or without it (frames=timer is passed on, for a headless browser).

import * as THREE from 'three';
import { drawMenu, pageAt, walker } from '/controls.js';
import { stage } from '/stage.js';

const params = new URLSearchParams(location.search);
const overlay = document.getElementById('overlay');
const errorLine = document.getElementById('error');
const colourSelect = document.getElementById('colour');
const fullBox = document.getElementById('full');
if (params.get('hud') === '0') {
  overlay.hidden = true;
  document.getElementById('controls').hidden = true;
}
// Whatever fails is said on the page, not only in the console.
addEventListener('error', (e) => { errorLine.textContent = String(e.message); });
addEventListener('unhandledrejection', (e) => { errorLine.textContent = String(e.reason?.message ?? e.reason); });

async function getJson(url) {
  const r = await fetch(url);
  const body = await r.json();
  if (!r.ok) throw new Error(`${url}: ${body.error ?? r.status}`);
  return body;
}

const vec3 = (s) => s.split(',').map(Number);

// --- the database and its grid ------------------------------------------------------------
const info = await getJson('/info');
const [x0, y0, z0, x1, y1, z1] = info.grid.region;
const dims = info.grid.dims;
const cellSize = [(x1 - x0) / dims[0], (y1 - y0) / dims[1], (z1 - z0) / dims[2]];

/** The cell holding p, or null outside the grid (the server's rule: upper cell on a border). */
function cellOf(p) {
  const c = [p.x - x0, p.y - y0, p.z - z0].map((d, k) => Math.floor(d / cellSize[k]));
  const inside = [p.x, p.y, p.z].every((v, k) => v >= info.grid.region[k] && v <= info.grid.region[k + 3]);
  return inside ? c.map((v, k) => Math.min(v, dims[k] - 1)) : null;
}

// --- the scene ----------------------------------------------------------------------------
const { renderer, scene, camera } = stage({ far: Math.hypot(x1 - x0, z1 - z0) * 1.5 });
addEventListener('resize', () => {
  camera.aspect = innerWidth / innerHeight;
  camera.updateProjectionMatrix();
  renderer.setSize(innerWidth, innerHeight);
});

const start = params.has('at') ? vec3(params.get('at')) : [(x0 + x1) / 2, (y0 + y1) / 2, (z0 + z1) / 2];
camera.position.set(...start);
const controls = walker(camera, renderer.domElement, info.grid);
controls.lookAlong(params.has('look') ? vec3(params.get('look')) : [1, 0, 0]);
/** Hands the walk to the 3D Tiles page, with the plugin (`tiles`) or without (`tiles-alone`). */
function drawTiles(how) {
  const extra = { plugin: how === 'tiles' ? '1' : '0' };
  if (params.has('frames')) extra.frames = params.get('frames');
  location.replace(pageAt('/tiles.html', camera, controls.look(), extra));
}
drawMenu('query').addEventListener('change', (e) => {
  if (e.target.value !== 'query') drawTiles(e.target.value);
});
if (['tiles', 'tiles-alone'].includes(params.get('draw'))) drawTiles(params.get('draw'));

// --- meshes: one stored LOD record per URL --------------------------------------------------
const geometries = new Map(); // url -> Promise<BufferGeometry>
let bytesLoaded = 0;

/** Our .glb: one mesh, one primitive, float VEC3 positions and uint32 indices. */
function parseGlb(buf) {
  const dv = new DataView(buf);
  if (dv.getUint32(0, true) !== 0x46546c67) throw new Error('not a glb');
  const jsonLen = dv.getUint32(12, true);
  const json = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 20, jsonLen)));
  const bin = 20 + jsonLen + 8;
  const prim = json.meshes[0].primitives[0];
  const slice = (a, size) => {
    const acc = json.accessors[a];
    const at = bin + (json.bufferViews[acc.bufferView].byteOffset ?? 0) + (acc.byteOffset ?? 0);
    return buf.slice(at, at + acc.count * size);
  };
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(slice(prim.attributes.POSITION, 12)), 3));
  g.setIndex(new THREE.BufferAttribute(new Uint32Array(slice(prim.indices, 4)), 1));
  g.computeBoundingSphere();
  return g;
}

function geometry(url) {
  if (!geometries.has(url)) {
    geometries.set(url, fetch(url).then(async (r) => {
      if (!r.ok) throw new Error(`${url}: ${(await r.json()).error}`);
      const buf = await r.arrayBuffer();
      bytesLoaded += buf.byteLength;
      return parseGlb(buf);
    }));
  }
  return geometries.get(url);
}

// --- colours -------------------------------------------------------------------------------
const lodPalette = [0x4c9a2a, 0xa4c639, 0xf1c232, 0xe69138, 0xcc4125, 0x990000, 0x741b47, 0x351c75];
function colourOf(item, mode) {
  if (mode === 'dov') {
    // log10 DoV from 1e-6 (blue) to 1e-1 (red).
    const t = Math.min(1, Math.max(0, (Math.log10(Math.max(item.dov, 1e-7)) + 6) / 5));
    return new THREE.Color().setHSL((1 - t) * 0.66, 0.85, 0.5);
  }
  if (mode === 'lod') return new THREE.Color(lodPalette[Math.min(item.lod, lodPalette.length - 1)]);
  return new THREE.Color(item.kind === 'node' ? 0xc8b89a : 0xd8d4cc);
}

// --- what is drawn ----------------------------------------------------------------------------
const drawn = new Map(); // item key -> { mesh, item }
let answer = null;
let status = 'loading';

function key(item) {
  return `${item.kind}:${item.id}:${item.lod}`;
}

/** Draws exactly `items`. Called only through the `pending` chain, so never twice at once. */
async function show(items) {
  const mode = colourSelect.value;
  const wanted = new Map(items.map((i) => [key(i), i]));
  for (const [k, d] of drawn) {
    if (!wanted.has(k)) {
      scene.remove(d.mesh);
      d.mesh.material.dispose();
      drawn.delete(k);
    }
  }
  await Promise.all([...wanted].filter(([k]) => !drawn.has(k)).map(async ([k, item]) => {
    const g = await geometry(item.mesh);
    const mesh = new THREE.Mesh(g, new THREE.MeshPhongMaterial({ color: colourOf(item, mode), flatShading: true }));
    if (item.transform) {
      mesh.matrixAutoUpdate = false;
      mesh.matrix.fromArray(item.transform);
    }
    scene.add(mesh);
    drawn.set(k, { mesh, item });
  }));
}

function recolour() {
  for (const d of drawn.values()) d.mesh.material.color = colourOf(d.item, colourSelect.value);
}
colourSelect.value = params.get('colour') ?? 'shading';
colourSelect.addEventListener('change', recolour);

let cell = null;
let pending = Promise.resolve();
let fullScene = null;

function queryUrl(p) {
  const q = new URLSearchParams({ at: `${p.x},${p.y},${p.z}` });
  for (const k of ['eta', 'mode', 'lod_rule']) if (params.has(k)) q.set(k, params.get(k));
  return `/query?${q}`;
}

function onMove() {
  const c = cellOf(camera.position);
  const id = c && c.join(',');
  if (id === cell) return;
  cell = id;
  if (!c) {
    status = 'outside the grid';
    return;
  }
  const at = camera.position.clone();
  pending = pending.then(async () => {
    if (fullBox.checked) return;
    status = 'loading';
    answer = await getJson(queryUrl(at));
    await show(answer.items);
    status = 'ready';
    redraw();
    document.body.dataset.state = 'ready';
  }).catch((e) => {
    errorLine.textContent = String(e.message ?? e);
    status = 'error';
  });
}

fullBox.addEventListener('change', () => {
  pending = pending.then(async () => {
    if (fullBox.checked) {
      fullScene ??= await getJson('/scene');
      await show(fullScene.items);
    } else if (answer) {
      await show(answer.items);
    }
  }).catch((e) => { errorLine.textContent = String(e.message ?? e); });
});

// --- moving: keyboard and mouse (controls.js), or a recorded walk ----------------------------
let walk = null;
let walkStep = 0;
if (params.has('walk')) {
  const q = new URLSearchParams({ kind: params.get('walk') });
  if (params.has('steps')) q.set('steps', params.get('steps'));
  walk = await getJson(`/recorded-walk?${q}`);
}

/** Follows the walk: ten steps a second at most, each once the last one's meshes are in. On a
 * timer, not the frame loop, so that it also runs where frames are rare (a headless browser). */
async function runWalk() {
  while (walkStep < walk.steps.length) {
    const s = walk.steps[walkStep++];
    camera.position.set(...s.at);
    controls.lookAlong(s.look);
    onMove();
    await pending;
    redraw();
    await new Promise((resolve) => setTimeout(resolve, 100));
  }
  status = `walk done, ${walk.steps.length} steps`;
  redraw();
  document.body.dataset.walk = 'done';
}

// --- the frame loop and the overlay -----------------------------------------------------------
let last = performance.now();
let frameMs = 0;

function redraw() {
  renderer.render(scene, camera);
  const s = answer?.stats;
  const faces = [...drawn.values()].reduce((n, d) => n + d.item.faces, 0);
  overlay.textContent = [
    `cell     ${cell ?? '–'} (${status})`,
    `items    ${drawn.size}${fullBox.checked ? ' (full scene)' : ''}`,
    `faces    ${faces}`,
    `pages    ${s ? s.pages_read : '–'} read by the last query`,
    `loaded   ${(bytesLoaded / 1e6).toFixed(2)} MB in ${geometries.size} meshes`,
    `frame    ${frameMs.toFixed(1)} ms`,
    ...(walk ? [`walk     step ${walkStep} of ${walk.steps.length}`] : []),
  ].join('\n');
}

function frame(now) {
  const dt = Math.min(0.1, (now - last) / 1000);
  frameMs = frameMs * 0.9 + (now - last) * 0.1;
  last = now;
  if (!walk) {
    controls.update(dt);
    onMove();
  }
  redraw();
  requestAnimationFrame(frame);
}
requestAnimationFrame(frame);
if (walk) runWalk();
