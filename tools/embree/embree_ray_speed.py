#!/usr/bin/env python3
"""Casts the rays that tools/src/bin/ray-speed.rs cast, with Intel Embree (embreex) on one thread,
checks that the hit objects agree with hdov's, and prints both speeds and their ratio. Times are the process's
CPU time (`time.process_time`; hdov's likewise), steadier than the wall clock on a shared machine.

    python3 tools/embree/embree_ray_speed.py OUT_DIR      (after `ray-speed SCENE OUT_DIR`)

Needs `pip install embreex numpy`. Same triangles (hdov's world triangles), same origins, same
texel-centre directions (forward component 1, not normalised), first hit. embreex's `run` casts
one `rtcIntersect1` after another on the calling thread; it gives no way to set `tnear`, so its
rays start at 0 where hdov's start at the near distance: texels whose Embree hit lies nearer than
`near` are counted apart. Coplanar faces of two objects may go either way in Embree (hdov takes
the lower id), so a few texels may differ; the count is printed.
"""
import json
import os
import sys
import time

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

NO_OBJECT = 0xFFFFFFFF
BACK_FACE_BIT = 1 << 31


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: embree_ray_speed.py OUT_DIR")
    d = sys.argv[1]
    meta = json.load(open(os.path.join(d, "hdov.json")))
    tris = np.fromfile(os.path.join(d, "triangles.f32"), dtype="<f4").reshape(-1, 3, 3)
    objects = np.fromfile(os.path.join(d, "objects.u32"), dtype="<u4")
    points = np.fromfile(os.path.join(d, "points.f32"), dtype="<f4").reshape(-1, 3)
    dirs = np.ascontiguousarray(np.fromfile(os.path.join(d, "directions.f32"), dtype="<f4").reshape(-1, 3))
    rays = len(dirs)
    near = meta["near"]

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, tris)  # a (n, 3, 3) array: one triangle per row, vertices unshared
    ids_file = open(os.path.join(d, "ids.u32"), "rb")

    total, total_wall = 0.0, 0.0
    differ, differ_near, hdov_hits = 0, 0, 0
    origins = np.empty_like(dirs)
    for p in points:
        origins[:] = p
        c0, t0 = time.process_time(), time.perf_counter()
        hit = scene.run(origins, dirs, output=1)
        total_wall += time.perf_counter() - t0
        total += time.process_time() - c0
        prim = hit["primID"]
        embree_ids = np.where(prim >= 0, objects[np.maximum(prim, 0)], NO_OBJECT).astype(np.uint32)
        hdov = np.frombuffer(ids_file.read(4 * rays), dtype="<u4")
        hdov_ids = np.where(hdov == NO_OBJECT, NO_OBJECT, hdov & ~np.uint32(BACK_FACE_BIT))
        hdov_hits += int((hdov != NO_OBJECT).sum())
        bad = embree_ids != hdov_ids
        nearer = bad & (prim >= 0) & (hit["tfar"] < near)
        differ += int(bad.sum())
        differ_near += int(nearer.sum())

    n = len(points)
    ms_embree = 1e3 * total / n
    ms_fast, ms_ref, ms_per_ray = meta["ms_per_point_fast"], meta["ms_per_point_reference"], meta["ms_per_point_per_ray"]
    print(f"{n} points, R = {meta['resolution']}, {meta['triangles']} triangles, {rays} rays per point, one thread each")
    print(f"embree (embreex rtcIntersect1):      {ms_embree:.2f} ms CPU per point, {rays / ms_embree / 1e3:.2f} M rays/s "
          f"(wall {1e3 * total_wall / n:.2f} ms)")
    print(f"hdov reference tracer:               {ms_ref:.2f} ms CPU per point, {rays / ms_ref / 1e3:.2f} M rays/s")
    print(f"hdov render_ids, one ray at a time:  {ms_per_ray:.2f} ms CPU per point, {rays / ms_per_ray / 1e3:.2f} M rays/s")
    print(f"hdov render_ids, ray packets:        {ms_fast:.2f} ms CPU per point, {rays / ms_fast / 1e3:.2f} M rays/s")
    print(f"ratio hdov/embree time per ray: reference {ms_ref / ms_embree:.3f}, one ray at a time "
          f"{ms_per_ray / ms_embree:.3f}, packets {ms_fast / ms_embree:.3f}")
    print(f"hit objects differing: {differ} of {n * rays} texels ({100 * differ / (n * rays):.4f} %), "
          f"{differ_near} of them Embree hits nearer than near = {near:.4g}; hdov hit {hdov_hits} texels")


if __name__ == "__main__":
    main()
