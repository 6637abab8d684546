"""Regenerate the procedural meshes in data/meshes (run from the repository root).

    python data/make_meshes.py
"""

from pathlib import Path

import trimesh

from diffwash._meshes import torus_knot, uv_sphere

HERE = Path(__file__).parent / "meshes"


def write(name, vertices, faces, normals):
    mesh = trimesh.Trimesh(vertices, faces, vertex_normals=normals, process=False)
    mesh.export(HERE / name, vertex_normal=True)
    print(f"{name}: {len(faces)} triangles")


if __name__ == "__main__":
    HERE.mkdir(exist_ok=True)
    write("knot-100k.ply", *torus_knot(1000, 50))
    write("knot-10k.ply", *torus_knot(250, 20))
    write("knot-1k.ply", *torus_knot(50, 10))
    write("sphere.ply", *uv_sphere(24, 48))
