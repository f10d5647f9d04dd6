// The database as a 3D Tiles tileset (/tiles/tileset.json) in 3DTilesRendererJS, with or without
// hdov's visibility plugin: the same walk both ways, and what each loads.
//
// URL parameters: plugin=1|0 (default 1), walk=straight|turning|back-and-forth and steps=N (a
// recorded walk; default: one view from at=X,Y,Z along look=DX,DY,DZ), errorTarget=PX (the
// renderer's screen-space error target; default its own, 16), frames=timer (frames from a timer,
// for a headless browser), reference=1 (also draw each view
// at full detail — every tile in the frustum refined to geometric error 0 — and give each
// frame's PSNR against it; referenceEvery=K: every K-th view only), nodes=query (the plugin draws
// a node's internal level only where the query stops, as `hdov query` does, and refines every
// other node), hud=0 (no overlay and no controls).
//
// Each view is held until nothing is queued, downloading or parsing for three frames. At the end
// the page writes its measures as JSON into #result and sets `data-state="done"` on <body>:
// per view the cell, the requests and bytes so far (tiles and, with the plugin, its visibility
// files apart) and the PSNR; and `requested`, every URL the tiles renderer fetched. Then, unless
// it followed a walk or draws on a timer (a headless measurement), the page is the viewer's 3D
// Tiles mode: walk on with the viewer's keys and mouse, or hand the walk back to the viewer.

import * as THREE from 'three';
import { TilesRenderer } from '/3d-tiles-renderer.min.js';
import { drawMenu, pageAt, walker } from '/controls.js';
import { HdovVisibilityPlugin } from '/hdov-tiles-plugin.js';
import { stage } from '/stage.js';

const params = new URLSearchParams(location.search);
// A headless browser draws no frames of its own, and the tiles renderer runs its download and
// parse queues on animation frames: there (frames=timer) frames come from a 16 ms timer.
if (params.get('frames') === 'timer') {
  globalThis.requestAnimationFrame = (cb) => setTimeout(() => cb(performance.now()), 16);
  globalThis.cancelAnimationFrame = (h) => clearTimeout(h);
}
const overlay = document.getElementById('overlay');
const errorLine = document.getElementById('error');
if (params.get('hud') === '0') {
  overlay.hidden = true;
  document.getElementById('controls').hidden = true;
}
const fail = (m) => {
  errorLine.textContent = String(m);
  document.body.dataset.state = 'failed';
};
addEventListener('error', (e) => fail(e.message));
addEventListener('unhandledrejection', (e) => fail(e.reason?.message ?? e.reason));

const vec3 = (s) => s.split(',').map(Number);
const withPlugin = params.get('plugin') !== '0';
const drawSelect = drawMenu(withPlugin ? 'tiles' : 'tiles-alone');

// --- the picture: as the viewer draws it, one pixel per pixel for stable PSNRs ---------------
const { renderer, scene, camera } = stage({ antialias: false, pixelRatio: 1 });
// Content without normals: flat shading, one material for every tile of both renderers.
const material = new THREE.MeshLambertMaterial({ color: 0xd8d4cc, flatShading: true });

/** `fetch`, adding each answer's request and bytes to `counts` (and its path to `counts.urls`,
 * where kept). */
function countingFetch(counts) {
  return (url, options) => fetch(url, options).then(async (r) => {
    const body = await r.arrayBuffer();
    counts.requests++;
    counts.bytes += body.byteLength;
    counts.urls?.push(new URL(url, location.href).pathname);
    return new Response(body, { status: r.status, statusText: r.statusText, headers: r.headers });
  });
}

/** Tiles of /tiles/tileset.json; `counts` tallies what its fetches bring. */
function tilesRenderer(counts, errorTarget) {
  const tiles = new TilesRenderer('/tiles/tileset.json');
  if (errorTarget != null) tiles.errorTarget = errorTarget;
  tiles.registerPlugin({ name: 'COUNT_FETCHES', fetchData: countingFetch(counts) });
  tiles.addEventListener('load-model', ({ scene: model }) => {
    model.traverse((o) => { if (o.isMesh) o.material = material; });
  });
  tiles.addEventListener('load-error', ({ error, url }) => fail(`${url}: ${error?.message ?? error}`));
  // The tileset is in 3D Tiles' z-up frame of the scene; turned back, it is in the scene's own.
  tiles.group.rotation.x = -Math.PI / 2;
  tiles.setCamera(camera);
  tiles.setResolutionFromRenderer(camera, renderer);
  scene.add(tiles.group);
  return tiles;
}

const counts = { requests: 0, bytes: 0, urls: [] };
const visibilityCounts = { requests: 0, bytes: 0 };
const errorTarget = params.has('errorTarget') ? Number(params.get('errorTarget')) : null;
const tiles = tilesRenderer(counts, errorTarget);
let plugin = null;
if (withPlugin) {
  plugin = new HdovVisibilityPlugin({
    queryNodes: params.get('nodes') === 'query',
    fetch: countingFetch(visibilityCounts),
  });
  tiles.registerPlugin(plugin);
}
const reference = params.get('reference') === '1' ? tilesRenderer({ requests: 0, bytes: 0, urls: [] }, 0) : null;
if (reference) {
  // Full detail of a street view can pass the cache's default 0.4 GiB: a tile the cache refuses
  // would be missing from the reference.
  Object.assign(reference.lruCache, { minSize: 1e6, maxSize: 1e6, minBytesSize: 6 * 2 ** 30, maxBytesSize: 8 * 2 ** 30 });
}
const referenceEvery = Math.max(1, Number(params.get('referenceEvery') ?? 1));

const frame = () => new Promise((resolve) => requestAnimationFrame(resolve));

/** Draws `t` alone until it has loaded what it wants for this view (at most `limit` frames). */
async function settle(t, limit = 3000) {
  for (const other of [tiles, reference]) if (other) other.group.visible = other === t;
  let quiet = 0;
  for (let n = 0; n < limit && quiet < 3; n++) {
    camera.updateMatrixWorld();
    t.update();
    renderer.render(scene, camera);
    await frame();
    const s = t.stats;
    const busy = t.isLoading || s.queued + s.downloading + s.parsing > 0 || t.rootTileset == null ||
      (t === tiles && plugin && (plugin.index == null || plugin.pending.size > 0));
    quiet = busy ? 0 : quiet + 1;
  }
  camera.updateMatrixWorld();
  t.update();
  renderer.render(scene, camera);
  const gl = renderer.getContext();
  const { width, height } = renderer.domElement;
  const pixels = new Uint8Array(width * height * 4);
  gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
  return pixels;
}

/** PSNR of `a` against `b` over RGB, in dB (100 where they are equal). */
function psnr(a, b) {
  let sum = 0;
  for (let i = 0; i < a.length; i += 4) {
    for (let c = 0; c < 3; c++) sum += (a[i + c] - b[i + c]) ** 2;
  }
  const mse = sum / (3 * (a.length / 4));
  return mse === 0 ? 100 : 10 * Math.log10((255 * 255) / mse);
}

function place(at, look) {
  camera.position.set(...at);
  const d = new THREE.Vector3(...look).normalize();
  camera.lookAt(camera.position.clone().add(d));
}

let views;
if (params.has('walk')) {
  const q = new URLSearchParams({ kind: params.get('walk') });
  if (params.has('steps')) q.set('steps', params.get('steps'));
  const r = await fetch(`/recorded-walk?${q}`);
  if (!r.ok) throw new Error(`/recorded-walk: ${r.status}`);
  views = (await r.json()).steps;
} else {
  views = [{ at: vec3(params.get('at') ?? '0,1.7,0'), look: vec3(params.get('look') ?? '1,0,0') }];
}

const steps = [];
for (const [k, v] of views.entries()) {
  place(v.at, v.look);
  const drawn = await settle(tiles);
  const step = {
    step: k,
    cell: plugin ? plugin.cell : null,
    requests: counts.requests,
    bytes: counts.bytes,
    visibility_requests: visibilityCounts.requests,
    visibility_bytes: visibilityCounts.bytes,
    visible_tiles: tiles.stats.visible,
  };
  if (reference && k % referenceEvery === 0) {
    step.psnr = psnr(drawn, await settle(reference));
    if (reference.stats.refused > 0) throw new Error(`the full-detail reference was refused ${reference.stats.refused} tiles`);
  }
  steps.push(step);
  overlay.textContent = `plugin   ${withPlugin ? 'on' : 'off'}\nview     ${k + 1} of ${views.length}\n` +
    `requests ${counts.requests}\nMB       ${(counts.bytes / 1e6).toFixed(2)}` +
    (step.psnr != null ? `\nPSNR     ${step.psnr.toFixed(1)} dB` : '');
}
if (reference) reference.group.visible = false;
tiles.group.visible = true;
document.getElementById('result').textContent = JSON.stringify({
  plugin: withPlugin,
  error_target: tiles.errorTarget,
  size: [renderer.domElement.width, renderer.domElement.height],
  steps,
  requested: counts.urls,
});
if (document.body.dataset.state !== 'failed') document.body.dataset.state = 'done';

// --- the viewer's 3D Tiles mode: walking on from the last view ---------------------------------
if (!params.has('walk') && params.get('frames') !== 'timer') {
  const info = await (await fetch('/info')).json();
  const controls = walker(camera, renderer.domElement, info.grid);
  controls.lookAlong(views.at(-1).look);
  drawSelect.addEventListener('change', () => {
    const page = drawSelect.value === 'query' ? '/' : '/tiles.html';
    const extra = drawSelect.value === 'query' ? {} : { plugin: drawSelect.value === 'tiles' ? '1' : '0' };
    location.href = pageAt(page, camera, controls.look(), extra);
  });
  let last = performance.now();
  const walkOn = (now) => {
    controls.update(Math.min(0.1, (now - last) / 1000));
    last = now;
    camera.updateMatrixWorld();
    tiles.update();
    renderer.render(scene, camera);
    overlay.textContent = `plugin   ${withPlugin ? `on, cell ${plugin.cell ?? '–'}` : 'off'}\n` +
      `tiles    ${tiles.stats.visible} drawn\nrequests ${counts.requests}\nMB       ${(counts.bytes / 1e6).toFixed(2)}`;
    requestAnimationFrame(walkOn);
  };
  requestAnimationFrame(walkOn);
}
