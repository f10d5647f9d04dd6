// What both pages draw in: `hdov render`'s background and near plane (so that pictures compare
// pixel by pixel), the viewer's lights and its 60° field of view, filling the window.

import * as THREE from 'three';

/** A renderer on the page, a lit scene and a camera seeing up to `far`. */
export function stage({ antialias = true, pixelRatio = window.devicePixelRatio, far = 1e5 } = {}) {
  const renderer = new THREE.WebGLRenderer({ antialias, preserveDrawingBuffer: true });
  renderer.setPixelRatio(pixelRatio);
  renderer.setSize(innerWidth, innerHeight);
  document.body.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xd6e4f0);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x556655, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.4);
  sun.position.set(0.4, 1, 0.25);
  scene.add(sun);
  const camera = new THREE.PerspectiveCamera(60, innerWidth / innerHeight, 0.05, far);
  return { renderer, scene, camera };
}
