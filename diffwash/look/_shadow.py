r"""Self-shadowing: the unlit glaze thickens where the object shadows itself.

The seed's model shades each point by its own normal only; a painter also
darkens the parts another part of the object hides from the light. A shadow
map gives it: the depth of the surface nearest the light, seen from the light,
at each texel of a light-space image; a point is in shadow where something lies
between it and the light.

The pieces, each a pure function of arrays:

1. `light_view_projection(vertices, direction)`: an orthographic projection
   along the (directional) light that fits the mesh's bounding sphere, in
   OpenGL's conventions (so a shader's light-space depth pass uses the very
   same matrix). Differentiable in the light direction.
2. The depth pass. A GPU rasterizes the mesh with that matrix into a depth
   texture (`diffwash._look_glsl.glsl_depth_pass`). diffwash's own rasterizer decides visibility
   by the clip-space `w`, which an orthographic projection sets to 1
   everywhere, so `light_clip` hands it positions with the same `x/w` and
   `y/w` (so the same coverage) and `w = 2 + z_ndc` (so the same nearest
   surface); `light_depth` then interpolates the orthographic depth over the
   triangle seen at each texel: `(z_ndc + 1) / 2`, what a depth buffer holds.
3. `shadow(depth, light_vp, positions, bias)`: the fraction of a 3x3-texel
   tent of depth comparisons (two bilinear percentage-closer taps per axis,
   Reeves et al. 1987) in which the point lies behind the stored depth. It is
   continuous in the point's position (the tent weights move with it), so
   gradients flow to the geometry and the light; its value is a step in
   `bias`, whose gradient is 0.

The unlit thickness then becomes `u + k_shadow * s * (k_unlit - u)`
(`diffwash.look.surface_terms`): a shadowed point is painted as if it faced
away from the light.

**References:**

- L. Williams, "Casting curved shadows on curved surfaces", SIGGRAPH 1978.
- W. T. Reeves, D. H. Salesin and R. L. Cook, "Rendering antialiased shadows
  with depth maps", SIGGRAPH 1987 (percentage-closer filtering).
- G. Smedresman, "Hardware Accelerated Pigment-Based Rendering System", future
  work ("self-shadowing is also an extremely important cue").
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int

from ._xla import apart

__all__ = [
    "light_view_projection",
    "light_clip",
    "light_depth",
    "shadow",
    "DEFAULT_BIAS",
    "SHADOW_MAP_SIZE",
    "SHADOW_TAPS",
    "normal_offset",
]

#: The depth bias (in depth-buffer units, [0, 1] over the light's depth range) that keeps a lit
#: surface from shadowing itself on the knot (with `normal_offset`).
DEFAULT_BIAS = 0.004
#: Texels per side of the light's depth map. 512 keeps the lookups in a CPU's caches (a 1024^2 map made
#: the JAX lookups about twice as slow, benchmarks/bench_look.py) and gives the soft-edged shadows a
#: wash wants; the 3x3 tent softens them over about 3 texels.
SHADOW_MAP_SIZE = 512
#: Texels per axis of the percentage-closer filter: 3 (a tent over 3x3 texels) or 2 (one bilinear tap).
SHADOW_TAPS = 3
_MARGIN = 1.02  # the frustum's half-size over the bounding sphere's radius


def normal_offset(light_vp: Float[ArrayLike, "4 4"], size: int = SHADOW_MAP_SIZE, texels: float = 1.5) -> float:
    """`texels` light-map texels in world units: the `normal_offset` that keeps lit surfaces out of their own shadow."""
    scale = float(np.linalg.norm(np.asarray(light_vp, np.float64)[0, :3]))  # 1 / the frustum's half-size
    return float(texels * 2 / (scale * size))


def _safe_normalize(v: Array) -> Array:
    n2 = jnp.sum(v * v)
    ok = n2 > 0
    return jnp.where(ok, v / jnp.sqrt(jnp.where(ok, n2, 1.0)), jnp.zeros_like(v).at[2].set(1.0))


def light_view_projection(vertices: Float[ArrayLike, "V 3"], direction: Float[ArrayLike, "3"]) -> Float[Array, "4 4"]:
    r"""An orthographic world-to-clip matrix looking along a directional light, fitting the mesh.

    The view looks from the light (`direction` points towards it, any length)
    at the centre `c` of the mesh's bounding box; the frustum is the cube of
    half-size `1.02 r` around `c` (`r` the largest distance of a vertex from
    `c`), so any orientation of the light sees the whole mesh. OpenGL's
    conventions: `z_ndc = -1` nearest the light, depth `(z_ndc + 1) / 2`.

    **Returns:**

    `(4, 4)`, row-major (`clip = VP @ [p, 1]`); differentiable in `direction`
    (and in `vertices` through `c` and `r`).
    """
    v = jnp.asarray(vertices)
    d = _safe_normalize(jnp.asarray(direction, v.dtype))
    c = 0.5 * (jnp.min(v, axis=0) + jnp.max(v, axis=0))
    r = jnp.sqrt(jnp.max(jnp.sum((v - c) ** 2, axis=1))) * _MARGIN
    # A basis with z towards the light; "up" is the world axis least aligned with it.
    axes = jnp.eye(3, dtype=v.dtype)
    up = axes[jnp.argmin(jnp.abs(d))]
    x = jnp.cross(up, d)
    x = x / jnp.linalg.norm(x)
    y = jnp.cross(d, x)
    rot = jnp.stack([x, y, d])  # world -> light eye (the light looks down -z)
    t = -(rot @ c) - jnp.asarray([0.0, 0.0, 2.0], v.dtype) * r  # the eye sits 2r from c towards the light
    view = jnp.concatenate([jnp.concatenate([rot, t[:, None]], axis=1), jnp.asarray([[0.0, 0.0, 0.0, 1.0]], v.dtype)])
    near, far = r, 3 * r
    zero = jnp.zeros_like(r)
    one = jnp.ones_like(r)
    proj = jnp.stack(
        [
            jnp.stack([1 / r, zero, zero, zero]),
            jnp.stack([zero, 1 / r, zero, zero]),
            jnp.stack([zero, zero, -2 / (far - near), -(far + near) / (far - near)]),
            jnp.stack([zero, zero, zero, one]),
        ]
    )
    return proj @ view


def _project(points: Array, vp: Array) -> Array:
    return points @ vp[:3, :3].T + vp[:3, 3]


def light_clip(vertices: Float[ArrayLike, "V 3"], light_vp: Float[ArrayLike, "4 4"]) -> Float[Array, "V 4"]:
    """Clip positions for a rasterizer that orders fragments by `w`: the orthographic view, `w = 2 + z_ndc`.

    `x/w`, `y/w`, `z/w` are the orthographic NDC, so coverage is the light
    view's; `w` grows with the distance from the light, so the nearest surface
    wins, as in a depth buffer.
    """
    ndc = _project(jnp.asarray(vertices), jnp.asarray(light_vp))
    w = 2 + ndc[:, 2:3]
    return jnp.concatenate([ndc * w, w], axis=1)


def light_depth(
    vertices: Float[ArrayLike, "V 3"], faces: Int[ArrayLike, "F 3"], light_vp: Float[ArrayLike, "4 4"], tri_id: Int[ArrayLike, "S S"]
) -> Float[Array, "S S"]:
    """The shadow map: depth `(z_ndc + 1) / 2` of the surface seen at each texel centre, 1 where none.

    **Arguments:**

    - `vertices`, `faces`: the mesh.
    - `light_vp`: from `light_view_projection`.
    - `tri_id`: the triangle seen at each texel (row 0 at the top, -1 where
      none), from a rasterizer run on `light_clip(vertices, light_vp)`.

    **Returns:**

    `(S, S')` depths in [0, 1], row 0 at the top (the light's `y_ndc = 1`);
    differentiable in `vertices` and `light_vp`.
    """
    tri_id = jnp.asarray(tri_id)
    rows, cols = tri_id.shape
    ndc = _project(jnp.asarray(vertices), jnp.asarray(light_vp))
    # Per face, the depth as a plane z = z0 + zx x + zy y over the light's NDC (the barycentric
    # interpolation written out), so that each texel reads 3 numbers of its face instead of its 3 corners.
    f = jnp.asarray(faces)
    a, b, c = ndc[f[:, 0]], ndc[f[:, 1]], ndc[f[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    ok = area != 0
    safe = jnp.where(ok, area, 1.0)
    db, dc = (b[:, 2] - a[:, 2]) / safe, (c[:, 2] - a[:, 2]) / safe
    zx = db * (c[:, 1] - a[:, 1]) - dc * (b[:, 1] - a[:, 1])
    zy = dc * (b[:, 0] - a[:, 0]) - db * (c[:, 0] - a[:, 0])
    z0 = a[:, 2] - zx * a[:, 0] - zy * a[:, 1]
    planes = jnp.stack([z0, zx, zy, ok.astype(z0.dtype)], axis=1)
    q = apart(lambda planes, tri: planes[jnp.maximum(tri, 0)], planes, tri_id)  # (S, S, 4)
    x = (jnp.arange(cols) + 0.5) / cols * 2 - 1
    y = 1 - (jnp.arange(rows) + 0.5) / rows * 2
    z = q[..., 0] + q[..., 1] * x[None, :] + q[..., 2] * y[:, None]
    return jnp.where((tri_id >= 0) & (q[..., 3] > 0), jnp.clip((z + 1) / 2, 0.0, 1.0), 1.0)


def _filter(t: Array, n: int, taps: int) -> tuple[list[Array], list[Array]]:
    """Indices (clamped) and weights of the PCF filter at texel coordinate `t` (texel `j` spans `[j, j + 1]`).

    `taps = 2`: one bilinear tap, `k0 = floor(t - 1/2)`, `g = t - 1/2 - k0`, weights `1 - g, g`.
    `taps = 3`: the mean of two bilinear taps at `t +- 1/2`: `k0 = floor(t - 1)`, `g = t - 1 - k0`,
    weights `(1 - g)/2, 1/2, g/2` on `k0, k0 + 1, k0 + 2` (a tent).
    """
    q = t - (0.5 if taps == 2 else 1.0)
    k0 = jnp.floor(q)
    g = q - k0
    k0 = k0.astype(jnp.int32)
    idx = [jnp.clip(k0 + i, 0, n - 1) for i in range(taps)]
    if taps == 2:
        return idx, [1 - g, g]
    return idx, [(1 - g) / 2, jnp.full_like(g, 0.5), g / 2]


def shadow(
    depth: Float[ArrayLike, "S S"],
    light_vp: Float[ArrayLike, "4 4"],
    positions: Float[ArrayLike, "*b 3"],
    bias: Float[ArrayLike, ""] = DEFAULT_BIAS,
    *,
    normals: Float[ArrayLike, "*b 3"] | None = None,
    normal_offset: Float[ArrayLike, ""] = 0.0,
    taps: int = SHADOW_TAPS,
) -> Float[Array, "*b"]:
    r"""How much each point is in its own shadow, in [0, 1] (1: fully hidden from the light).

    The point's light-space depth minus `bias`, compared with the shadow map's
    (`<=`: lit, as `GL_LEQUAL`) at the texels around it: with `taps = 3` the
    3x3 texels weighted by the tent `[(1 - g)/2, 1/2, g/2]` per axis (`g` the
    point's fractional texel position), the average of two bilinear
    percentage-closer taps half a texel either side; with `taps = 2` one
    bilinear percentage-closer tap (2x2 texels, what a GPU's `sampler2DShadow`
    does with linear filtering). Texels past the map's edge repeat its edge.

    **Arguments:**

    - `depth`: the shadow map (`light_depth`), row 0 at the top.
    - `light_vp`: the light's matrix (`light_view_projection`).
    - `positions`: world-space points.
    - `bias`: subtracted from the point's depth (acne against peter-panning).
    - `normals`, `normal_offset`: look the point up at `P + normal_offset * N`
      instead (world units; about a texel's width keeps surfaces at grazing
      light from shadowing themselves, `normal_offset()`).
    - `taps`: 2 or 3 texels per axis (static).

    **Returns:**

    The shadow factor, shape `(*b,)`: continuous and differentiable in
    `positions` and `light_vp` (through the filter weights).
    """
    if taps not in (2, 3):
        raise ValueError(f"taps must be 2 or 3, got {taps}")
    depth = jnp.asarray(depth)
    rows, cols = depth.shape
    P = jnp.asarray(positions)
    if normals is not None:
        P = P + normal_offset * jnp.asarray(normals)
    ndc = _project(P, jnp.asarray(light_vp))
    d = (ndc[..., 2] + 1) / 2 - bias
    cx, wx = _filter((ndc[..., 0] + 1) / 2 * cols, cols, taps)  # texel centres at j + 0.5
    cy, wy = _filter((1 - ndc[..., 1]) / 2 * rows, rows, taps)

    def reads(depth, d, cx, cy, wx, wy):  # apart: XLA would recompute the projection at every read
        lit = 0.0
        for i in range(taps):
            for j in range(taps):
                lit = lit + wy[i] * wx[j] * (d <= depth[cy[i], cx[j]]).astype(d.dtype)
        return 1 - lit

    return apart(reads, depth, d, cx, cy, wx, wy)
