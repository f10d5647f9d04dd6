// HdovVisibilityPlugin: precomputed visibility for 3DTilesRendererJS (npm `3d-tiles-renderer`).
//
// A tileset written by `hdov export DB --3dtiles DIR` (or served by `hdov serve` under /tiles/)
// names, in its root's `extras.hdov.visibility`, an index of view cells; each cell has a small
// file of the tiles it may see and where the query stops refining (docs/format.md, "3D Tiles
// out"). With this plugin registered, the renderer finds the camera's cell on every update and
//
//   (a) never loads or refines a tile the cell cannot see: such a tile is out of view, so its
//       subtree is never visited (nor its subtree's tileset fetched); a node's coarse level comes
//       in slices, one per entry it stands for, and only the slices of entries the cell may see
//       are drawn;
//   (b) refines a stopped subtree (seen with DoV ≤ η) no further than the query draws it: the
//       stop's tile gets no screen-space error, so the renderer keeps it as a leaf.
//
// Nothing of the tileset loads before the index and the camera's first cell file are read; outside
// every view cell the renderer decides alone.
//
//   import { HdovVisibilityPlugin } from './hdov-tiles-plugin.js';
//   tiles.registerPlugin(new HdovVisibilityPlugin());
//
// The renderer's `loadSiblings` and `loadAncestors` are turned off: with them it downloads every
// sibling of a tile it refines into, hidden ones included.

/** Reads one cell file (`HDVC`, version 1): `{ cell, dov: Map(key → DoV), stops: Map(key → level) }`. */
export function decodeCell(buffer) {
  const bytes = new Uint8Array(buffer);
  const view = new DataView(buffer);
  if (bytes.length < 20 || String.fromCharCode(...bytes.subarray(0, 4)) !== 'HDVC') throw new Error('not a cell visibility file');
  const version = view.getUint32(4, true);
  if (version !== 1) throw new Error(`cell file version ${version}, this reader reads 1`);
  const cell = view.getUint32(8, true);
  const n = view.getUint32(12, true);
  const s = view.getUint32(16, true);
  let at = 20;
  const varint = () => {
    let x = 0;
    for (let scale = 1; ; scale *= 128) {
      if (at >= bytes.length) throw new Error('cell file ends early');
      const b = bytes[at++];
      x += (b & 0x7f) * scale;
      if ((b & 0x80) === 0) return x;
    }
  };
  const keys = new Array(n);
  let last = 0;
  for (let i = 0; i < n; i++) keys[i] = last += varint();
  if (at + 2 * n > bytes.length) throw new Error('cell file ends early');
  const dov = new Map();
  for (let i = 0; i < n; i++, at += 2) dov.set(keys[i], 2 ** (view.getUint16(at, true) / 1024 - 32));
  const stops = new Map();
  last = 0;
  for (let i = 0; i < s; i++) {
    last += varint();
    stops.set(last, varint());
  }
  if (at !== bytes.length) throw new Error('cell file has bytes after its last stop');
  return { cell, dov, stops };
}

/** The view cell holding `p` ([x, y, z] in the scene's frame) in the index's `grid`, or null. */
export function locateCell(grid, p) {
  const [x0, y0, z0, x1, y1, z1] = grid.region;
  const lo = [x0, y0, z0];
  const hi = [x1, y1, z1];
  if (!p.every((v, a) => Number.isFinite(v) && v >= lo[a] && v <= hi[a])) return null;
  const size = grid.dims.map((d, a) => (hi[a] - lo[a]) / d);
  const c = p.map((v, a) => Math.min(Math.max(Math.floor((v - lo[a]) / size[a]), 0), grid.dims[a] - 1));
  const [nx, , nz] = grid.dims;
  const id = (c[1] * nz + c[2]) * nx + c[0];
  if (grid.present == null) return id;
  // The present set's runs: the cell's rank among present cells, or null when absent.
  let rank = 0;
  let present = false;
  for (const [first, end] of grid.present) {
    if (id >= end) { rank += end - first; continue; }
    if (id >= first) { rank += id - first; present = true; }
    break;
  }
  if (!present) return null;
  if (grid.places == null) return id;
  // The point's square among the cell's 8 × 8 (bit 8·z + x).
  const square = (a) => Math.min(Math.max(Math.floor(((p[a] - lo[a]) / size[a] - c[a]) * 8), 0), 7);
  const bit = BigInt(square(2) * 8 + square(0));
  const has = (hex) => ((BigInt('0x' + hex) >> bit) & 1n) === 1n;
  if (has(grid.places[rank])) return id;
  const lattice = grid.dims[0] * grid.dims[1] * grid.dims[2];
  const k = grid.parts.findIndex(([cell, mask]) => cell === id && has(mask));
  return k < 0 ? null : lattice + k;
}

export class HdovVisibilityPlugin {
  /** `fetch`: how the index and cell files are fetched (to count their bytes, say). */
  constructor({ fetch: fetchFn = (url) => fetch(url), queryNodes = false } = {}) {
    this.name = 'HDOV_VISIBILITY_PLUGIN';
    this.fetch = fetchFn;
    this.queryNodes = queryNodes;
    this.index = null;
    this.indexUrl = null;
    this.sceneFromTileset = null;
    this.nodeCount = 0;
    // The camera's cell and its file (`visibility`), and files by cell.
    this.cell = null;
    this.visibility = null;
    this.files = new Map();
    this.pending = new Map();
  }

  init(tiles) {
    this.tiles = tiles;
    tiles.loadSiblings = false;
    tiles.loadAncestors = false;
    // (b) A stop's tile keeps no error: the renderer does not refine past it. A plugin's own
    // error can only raise the renderer's, so the instance's camera error is wrapped.
    const cameraError = tiles.calculateTileViewError.bind(tiles);
    tiles.calculateTileViewError = (tile, target) => {
      cameraError(tile, target);
      if (this.isStop(tile)) target.error = 0;
      else if (this.mustRefine(tile)) target.error = Infinity;
    };
    this._onLoad = ({ tileset, url }) => this.loadIndex(tileset, url);
    tiles.addEventListener('load-root-tileset', this._onLoad);
    this._onUpdate = () => this.followCamera();
    tiles.addEventListener('update-before', this._onUpdate);
  }

  dispose() {
    this.tiles.removeEventListener('load-root-tileset', this._onLoad);
    this.tiles.removeEventListener('update-before', this._onUpdate);
  }

  async loadIndex(tileset, url) {
    const path = tileset?.extras?.hdov?.visibility;
    if (!path) return; // not an hdov tileset: the plugin does nothing
    this.indexUrl = new URL(path, new URL(url, location.href)).toString();
    const r = await this.fetch(this.indexUrl);
    if (!r.ok) throw new Error(`${this.indexUrl}: ${r.status}`);
    const text = await r.text();
    this.index = JSON.parse(text);
    this.nodeCount = this.index.nodeCount;
    this.sceneFromTileset = this.index.sceneFromTileset;
    this.tiles.dispatchEvent({ type: 'needs-update' });
  }

  /** The camera's position in the scene's frame. */
  cameraPoint() {
    const camera = this.tiles.cameras[0];
    if (!camera || !this.sceneFromTileset) return null;
    camera.updateMatrixWorld();
    const e = camera.matrixWorld.elements;
    // World → the tileset's frame (the inverse of the group's matrix), then → the scene's frame.
    const g = this.tiles.group.matrixWorld.clone().invert().elements;
    const w = [e[12], e[13], e[14]];
    const t = [0, 1, 2].map((r) => g[r] * w[0] + g[4 + r] * w[1] + g[8 + r] * w[2] + g[12 + r]);
    const m = this.sceneFromTileset;
    return [0, 1, 2].map((r) => m[r] * t[0] + m[4 + r] * t[1] + m[8 + r] * t[2] + m[12 + r]);
  }

  followCamera() {
    if (!this.index) return;
    const p = this.cameraPoint();
    const cell = p && locateCell(this.index.grid, p);
    if (cell === this.cell) return;
    this.cell = cell;
    if (cell == null) {
      this.visibility = null;
      return;
    }
    if (this.files.has(cell)) {
      this.visibility = this.files.get(cell);
      return;
    }
    // Until the new cell's file arrives, the last cell's visibility stays.
    if (!this.pending.has(cell)) this.pending.set(cell, this.loadCell(cell));
  }

  async loadCell(cell) {
    const url = new URL(this.index.cells.replace('{cell}', String(cell)), this.indexUrl).toString();
    const r = await this.fetch(url);
    if (!r.ok) throw new Error(`${url}: ${r.status}`);
    const buffer = await r.arrayBuffer();
    const file = decodeCell(buffer);
    this.files.set(cell, file);
    this.pending.delete(cell);
    if (this.cell === cell) {
      this.visibility = file;
      this.tiles.dispatchEvent({ type: 'needs-update' });
    }
  }

  /** The tile's visibility key, or null for tiles that are not hdov's. */
  key(tile) {
    const h = tile.extras?.hdov;
    if (h == null) return null;
    return h.node != null ? h.node : this.nodeCount + h.object;
  }

  /** Whether a drawn level of a node must not be drawn here: with `queryNodes`, every node the
   * query does not stop at is refined, as `hdov query` refines it. */
  mustRefine(tile) {
    const h = tile.extras?.hdov;
    return this.queryNodes && this.visibility != null && h?.node != null && h.level != null;
  }

  /** Whether the query stops refining at this tile (a stop of the camera's cell). */
  isStop(tile) {
    const v = this.visibility;
    const h = tile.extras?.hdov;
    if (!v || h == null || h.level == null) return false;
    const level = v.stops.get(this.key(tile));
    // Levels count from full detail (0); a chain goes from coarse to fine, so the first of its
    // tiles at the stop's level or finer is where the query's level is drawn (a level the chain
    // left out claims the error of the finer one kept).
    return level != null && h.level <= level;
  }

  // (a) What the cell cannot see is out of view, and so is all of an hdov tileset until the
  // index and the camera's first cell file are read (nothing hidden loads at the start). Outside
  // every view cell the renderer decides alone.
  calculateTileViewError(tile, target) {
    const key = this.key(tile);
    if (key == null) return false;
    const v = this.visibility;
    // A slice of a node's level stands for some of its entries (`entries`): it is drawn where
    // the cell may see one of them.
    const entries = tile.extras.hdov.entries;
    const seen = (k) => v.dov.has(k);
    if (v ? (entries ? entries.some(seen) : seen(key)) : this.index != null && this.cell == null) return false;
    target.inView = false;
    target.error = 0;
    return true;
  }
}
