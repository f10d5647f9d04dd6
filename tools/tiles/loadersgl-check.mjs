// A second 3D Tiles client reads hdov's tileset: vis.gl's loaders.gl (@loaders.gl/3d-tiles and
// @loaders.gl/tiles 4.5) parses DIR/tileset.json, and the subtree tilesets it names, as Tileset3D
// does for deck.gl, and for every tile
// this checks that its geometric error is at least each child's and that its box, as loaders.gl
// places it in the world, holds every vertex of its content (glTF y-up turned to z-up, then the
// tile's transforms, as the 3D Tiles spec draws content).
//
//   NODE_PATH=$(npm root -g) node tools/tiles/loadersgl-check.mjs DIR
//
// Prints one JSON line {tiles, contents, vertices, violations}; exits 1 when any check fails.
import { readFile } from 'node:fs/promises';
import { createRequire } from 'node:module';
import { dirname, join, resolve } from 'node:path';

// ES modules ignore NODE_PATH: the packages are required from the global folder it names.
const require = createRequire(join(resolve(process.env.NODE_PATH ?? '.'), 'index.js'));
const { parse } = require('@loaders.gl/core');
const { Tiles3DLoader } = require('@loaders.gl/3d-tiles');
const { GLTFLoader, postProcessGLTF } = require('@loaders.gl/gltf');
const { Tileset3D } = require('@loaders.gl/tiles');

const dir = resolve(process.argv[2]);

// A tileset's root as loaders.gl places it; a subtree tileset (a tile whose content is another
// tileset.json) under the transform of the tile that names it.
async function rootOf(path, modelMatrix) {
  const json = await parse(await readFile(path), Tiles3DLoader, { '3d-tiles': { isTileset: true } }, { url: path });
  const tileset = new Tileset3D(json, modelMatrix ? { loadTiles: false, modelMatrix } : { loadTiles: false });
  await tileset.tilesetInitializationPromise;
  return tileset.root;
}

const violations = [];
let tiles = 0;
let contents = 0;
let vertices = 0;
const stack = [[await rootOf(join(dir, 'tileset.json')), dir]];
while (stack.length) {
  const [t, base] = stack.pop();
  tiles++;
  const key = JSON.stringify(t.header.extras ?? {});
  for (const c of t.children) {
    if (c.lodMetricValue > t.lodMetricValue) violations.push(`${JSON.stringify(c.header.extras)}: error ${c.lodMetricValue} above its parent's ${t.lodMetricValue}`);
    stack.push([c, base]);
  }
  const uri = t.header.content?.uri;
  if (!uri) continue;
  if (uri.endsWith('.json')) {
    const sub = join(base, uri);
    const root = await rootOf(sub, t.computedTransform);
    if (root.lodMetricValue > t.lodMetricValue) violations.push(`${key}: ${uri}'s root error above the tile's`);
    stack.push([root, dirname(sub)]);
    continue;
  }
  contents++;
  const gltf = postProcessGLTF(await parse(await readFile(join(base, uri)), GLTFLoader, {}));
  const m = t.computedTransform; // the tile's transforms, root first, as loaders.gl composes them
  const bv = t.boundingVolume;
  const tolerance = 1e-6 * Math.max(1, ...bv.halfAxes.toArray().map(Math.abs));
  let outside = 0;
  for (const mesh of gltf.meshes) {
    for (const prim of mesh.primitives) {
      const p = prim.attributes.POSITION.value;
      for (let i = 0; i < p.length; i += 3) {
        // glTF y-up → z-up: (x, y, z) → (x, −z, y); then the tile's transform.
        const q = [p[i], -p[i + 2], p[i + 1]];
        const w = [0, 1, 2].map((r) => m[r] * q[0] + m[4 + r] * q[1] + m[8 + r] * q[2] + m[12 + r]);
        vertices++;
        if (bv.distanceSquaredTo(w) > tolerance * tolerance) outside++;
      }
    }
  }
  if (outside) violations.push(`${key}: ${outside} vertices of ${uri} outside its box`);
}
console.log(JSON.stringify({ tiles, contents, vertices, violations: violations.slice(0, 20) }));
process.exit(violations.length ? 1 : 0);
