"""Reads meshes with Open3D's Python package (Debian python3-open3d) and prints, per file, one line:
NAME VERTICES TRIANGLES HAS_COLORS HAS_NORMALS MEAN_R MEAN_G MEAN_B MIN_X MAX_X
Exit code 1 when a file cannot be read. Usage: python3 read_mesh_open3d.py FILE..."""
import sys

import numpy as np
import open3d as o3d

status = 0
for path in sys.argv[1:]:
    mesh = o3d.io.read_triangle_mesh(path)
    if len(mesh.vertices) == 0:
        print(f"{path}: Open3D read no vertices")
        status = 1
        continue
    v = np.asarray(mesh.vertices)
    c = np.asarray(mesh.vertex_colors) if mesh.has_vertex_colors() else np.zeros((1, 3))
    mean = c.mean(axis=0)
    print(path.split("/")[-1], len(mesh.vertices), len(mesh.triangles), int(mesh.has_vertex_colors()),
          int(mesh.has_vertex_normals()), f"{mean[0]:.6f} {mean[1]:.6f} {mean[2]:.6f}",
          f"{v[:, 0].min():.6f} {v[:, 0].max():.6f}")
sys.exit(status)
