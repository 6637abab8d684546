"""Procedural test meshes (a torus knot, a sphere), for examples, tests and benchmarks."""

from __future__ import annotations

import numpy as np

from ._lazy import lazy

trimesh = lazy("trimesh")

__all__ = ["torus_knot", "uv_sphere"]


def torus_knot(
    segments: int = 1000, sides: int = 50, p: int = 2, q: int = 3, radius: float = 0.16
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed (p, q) torus knot tube with `2 * segments * sides` triangles.

    The knot's centre line lies within a sphere of radius about 1 around the
    origin. Normals are the tube's exact ones.

    **Returns:**

    `(vertices (V, 3), faces (F, 3), normals (V, 3))`, faces wound
    counter-clockwise seen from outside.
    """
    t = np.linspace(0, 2 * np.pi, segments, endpoint=False)

    def curve(t):
        r = 0.62 + 0.28 * np.cos(q * t)
        return np.stack([r * np.cos(p * t), r * np.sin(p * t), 0.28 * np.sin(q * t)], axis=-1)

    c = curve(t)
    dt = 1e-4
    tangent = curve(t + dt) - curve(t - dt)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    # Parallel-transported frame, with the accumulated twist spread over the loop.
    normal = np.zeros_like(c)
    ref = np.cross(tangent[0], [0.0, 0.0, 1.0])
    if np.linalg.norm(ref) < 1e-6:
        ref = np.cross(tangent[0], [0.0, 1.0, 0.0])
    normal[0] = ref / np.linalg.norm(ref)
    for i in range(1, segments):
        n = normal[i - 1] - np.dot(normal[i - 1], tangent[i]) * tangent[i]
        normal[i] = n / np.linalg.norm(n)
    end = normal[-1] - np.dot(normal[-1], tangent[0]) * tangent[0]
    end /= np.linalg.norm(end)
    binormal0 = np.cross(tangent[0], normal[0])
    twist = np.arctan2(np.dot(end, binormal0), np.dot(end, normal[0]))
    angle = -twist * np.arange(segments) / segments
    binormal = np.cross(tangent, normal)
    n_rot = np.cos(angle)[:, None] * normal + np.sin(angle)[:, None] * binormal
    b_rot = np.cross(tangent, n_rot)

    phi = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    dirs = np.cos(phi)[None, :, None] * n_rot[:, None, :] + np.sin(phi)[None, :, None] * b_rot[:, None, :]
    vertices = (c[:, None, :] + radius * dirs).reshape(-1, 3)
    normals = dirs.reshape(-1, 3)

    i = np.arange(segments)[:, None]
    j = np.arange(sides)[None, :]
    a = i * sides + j
    b = ((i + 1) % segments) * sides + j
    c2 = ((i + 1) % segments) * sides + (j + 1) % sides
    d = i * sides + (j + 1) % sides
    faces = np.concatenate([np.stack([a, b, c2], -1).reshape(-1, 3), np.stack([a, c2, d], -1).reshape(-1, 3)])
    # Orient outwards: the first triangle's normal must agree with the tube normal.
    v = vertices[faces[0]]
    if np.dot(np.cross(v[1] - v[0], v[2] - v[0]), normals[faces[0]].sum(0)) < 0:
        faces = faces[:, ::-1]
    return vertices, np.ascontiguousarray(faces, dtype=np.int64), normals


def uv_sphere(rings: int = 32, sectors: int = 64, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed UV sphere with exact normals: `(vertices, faces, normals)`."""
    m = trimesh.creation.uv_sphere(radius=radius, count=[rings, sectors])
    m.merge_vertices()
    n = m.vertices / np.linalg.norm(m.vertices, axis=1, keepdims=True)
    return np.asarray(m.vertices), np.asarray(m.faces, np.int64), n
