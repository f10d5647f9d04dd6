// What both pages share to walk: keyboard and mouse (WASD or the arrows move on the ground plane,
// Shift four times as fast, R and F up and down, a drag turns the head), the "draw" menu, and
// the URL that hands a walk from one page to the other.

import * as THREE from 'three';

/** First-person controls of `camera`, listening on `dom` (drags) and the window (keys), walking
 * half a cell of `grid` (/info's) a second. */
export function walker(camera, dom, grid) {
  const [x0, , z0, x1, , z1] = grid.region;
  const speed = Math.min((x1 - x0) / grid.dims[0], (z1 - z0) / grid.dims[2]) * 0.5;
  let yaw = 0;
  let pitch = 0;
  const keys = new Set();
  addEventListener('keydown', (e) => keys.add(e.key.toLowerCase()));
  addEventListener('keyup', (e) => keys.delete(e.key.toLowerCase()));
  let dragging = null;
  dom.addEventListener('pointerdown', (e) => { dragging = [e.clientX, e.clientY]; });
  addEventListener('pointerup', () => { dragging = null; });
  addEventListener('pointermove', (e) => {
    if (!dragging) return;
    yaw -= (e.clientX - dragging[0]) * 0.004;
    pitch = Math.max(-1.5, Math.min(1.5, pitch - (e.clientY - dragging[1]) * 0.004));
    dragging = [e.clientX, e.clientY];
  });
  const aim = () => camera.rotation.set(pitch, yaw, 0, 'YXZ');
  return {
    /** Looks along direction `d` ([x, y, z]). */
    lookAlong(d) {
      yaw = Math.atan2(-d[0], -d[2]);
      pitch = Math.atan2(d[1], Math.hypot(d[0], d[2]));
      aim();
    },
    /** The view direction, as [x, y, z]. */
    look() {
      return camera.getWorldDirection(new THREE.Vector3()).toArray();
    },
    /** Moves and turns the camera by what the keys held and the drag did in `dt` seconds. */
    update(dt) {
      const forward = new THREE.Vector3(-Math.sin(yaw), 0, -Math.cos(yaw));
      const right = new THREE.Vector3(-forward.z, 0, forward.x);
      const step = speed * dt * (keys.has('shift') ? 4 : 1);
      if (keys.has('w') || keys.has('arrowup')) camera.position.addScaledVector(forward, step);
      if (keys.has('s') || keys.has('arrowdown')) camera.position.addScaledVector(forward, -step);
      if (keys.has('d') || keys.has('arrowright')) camera.position.addScaledVector(right, step);
      if (keys.has('a') || keys.has('arrowleft')) camera.position.addScaledVector(right, -step);
      if (keys.has('r')) camera.position.y += step;
      if (keys.has('f')) camera.position.y -= step;
      aim();
    },
  };
}

/** The "draw" menu, put first in #controls: hdov's answers from /query, or the database as
 * 3D Tiles with hdov's visibility plugin or without it; `current` chosen. */
export function drawMenu(current) {
  const select = document.createElement('select');
  select.id = 'draw';
  const choices = [['query', "hdov's answers (/query)"], ['tiles', '3D Tiles, hdov visibility plugin'], ['tiles-alone', '3D Tiles alone']];
  for (const [value, text] of choices) select.add(new Option(text, value));
  select.value = current;
  const label = document.createElement('label');
  label.append('draw ', select);
  document.getElementById('controls').prepend(label);
  return select;
}

/** The URL of `page` ('/' or '/tiles.html') at the camera's place and view, with `extra`
 * parameters: how one page hands the walk to the other. */
export function pageAt(page, camera, look, extra = {}) {
  const p = camera.position;
  const q = new URLSearchParams({ at: `${p.x},${p.y},${p.z}`, look: look.join(','), ...extra });
  return `${page}?${q}`;
}
