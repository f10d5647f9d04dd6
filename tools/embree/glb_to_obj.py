#!/usr/bin/env python3
"""Writes a glTF/GLB scene as one OBJ, one `o` group per scene-graph node that draws a mesh, in
world space (node transforms applied), so that hdov reads it with one object per part.

    python3 tools/embree/glb_to_obj.py IN.glb OUT.obj

Needs `pip install trimesh numpy`. Zero-area triangles are written as they are; hdov's OBJ import
drops them (the 2CylinderEngine sample: 121,496 triangles in the file, 110,336 after the drop).
"""
import sys

import numpy as np
import trimesh


def main():
    if len(sys.argv) != 3:
        sys.exit("usage: glb_to_obj.py IN.glb OUT.obj")
    scene = trimesh.load(sys.argv[1], force="scene")
    base = 1
    with open(sys.argv[2], "w") as out:
        for k, node in enumerate(scene.graph.nodes_geometry):
            transform, geometry = scene.graph[node]
            mesh = scene.geometry[geometry]
            if not hasattr(mesh, "faces") or len(mesh.faces) == 0:
                continue
            v = trimesh.transformations.transform_points(mesh.vertices, transform)
            faces = mesh.faces
            if np.linalg.det(transform[:3, :3]) < 0:
                faces = faces[:, ::-1]  # a mirroring node keeps its outward winding
            out.write(f"o {node}_{k}\n")
            out.write("".join(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in v))
            out.write("".join(f"f {a} {b} {c}\n" for a, b, c in faces + base))
            base += len(v)


if __name__ == "__main__":
    main()
