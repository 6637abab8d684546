r"""The renderer: visibility -> barycentrics -> thicknesses -> Kubelka-Munk glazes -> image.

`render(scene, params)` composes the nvdiffrast-like ops of this package with
the watercolour model of `diffwash.shading`:

1. `rasterize` (non-differentiable, cached): the triangle seen at each pixel.
2. `barycentrics` (differentiable in vertices and camera): perspective-correct
   barycentrics of the covered pixel centres.
3. Shading, per pixel or per vertex (Smedresman's two variants):

   - *per-pixel*: the normal (renormalised) and the position are interpolated;
     `V = normalize(eye - P)`; `shading.thicknesses(N, L, V)` at each pixel.
   - *per-vertex*: `shading.thicknesses` at the vertices (`V = normalize(eye -
     vertex)`), interpolated perspective-correctly.

   In both the Kubelka-Munk glazes (`shading.glaze`) are evaluated per pixel.
   Where back faces are drawn (open meshes), a back-facing triangle is shaded
   with its normals turned towards the eye (OpenGL's two-sided lighting).
4. Uncovered pixels show the bare paper.
5. Optionally `antialias` (differentiable): silhouette edges blend neighbouring
   pixels by the edge's analytic position, giving gradients with respect to
   vertex positions and camera.

Only covered pixels are shaded (a compacted list, padded to a bucket size), so
the cost follows the object's area on screen, not the image's.
"""

from __future__ import annotations

import collections
import functools
import zlib
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from . import shading
from ._barycentric import barycentrics
from ._interpolate import interpolate
from ._raster import Visibility, clip_positions, rasterize
from .pigments import Pigment

__all__ = ["render", "render_rgba", "render_thicknesses", "clear_visibility_cache"]

_CACHE_SIZE = 4
_cache: collections.OrderedDict[tuple, Visibility] = collections.OrderedDict()


def clear_visibility_cache() -> None:
    """Forget the visibilities `render` computed for concrete scenes."""
    _cache.clear()


def _is_concrete(tree: Any) -> bool:
    return not any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def _array_key(a: Any) -> tuple:
    a = np.ascontiguousarray(np.asarray(a))
    return (a.shape, a.dtype.str, zlib.crc32(a.view(np.uint8).reshape(-1)))


def _scene_key(scene: Any) -> tuple:
    """What visibility depends on: size, back-face mode, vertex and face contents, camera."""
    cam = scene.camera
    camera = tuple(np.asarray(getattr(cam, f), np.float64).tobytes() for f in ("eye", "target", "up", "fov_y", "near", "far"))
    return (
        scene.width,
        scene.height,
        scene.cull_backfaces,
        _array_key(scene.mesh.vertices),
        _array_key(scene.mesh.faces),
        camera,
    )


def _geometry(scene: Any) -> tuple:
    return (scene.mesh.vertices, scene.mesh.faces, scene.camera)


def _visibility(scene: Any, visibility: Visibility | None, antialias: bool) -> Visibility:
    """The scene's visibility: given, cached, or computed (on the host, or by a callback when traced)."""
    if visibility is not None:
        if (visibility.width, visibility.height) != (scene.width, scene.height):
            raise ValueError(
                f"visibility is for a {visibility.width}x{visibility.height} image, "
                f"the scene is {scene.width}x{scene.height}"
            )
        if antialias and visibility.silhouettes is None:
            from ._antialias import prepare

            visibility = prepare(scene, visibility)
        return visibility
    if not _is_concrete(_geometry(scene)):
        from ._antialias import traced_visibility

        return traced_visibility(scene, antialias)
    key = _scene_key(scene)
    vis = _cache.get(key)
    if vis is None:
        vis = rasterize(scene, antialias=antialias)
    elif antialias and vis.silhouettes is None:
        from ._antialias import prepare

        vis = prepare(scene, vis)
    _cache[key] = vis
    _cache.move_to_end(key)
    while len(_cache) > _CACHE_SIZE:
        _cache.popitem(last=False)
    return vis


def _int32(a: Any) -> Any:
    return a.astype(np.int32, copy=False) if isinstance(a, np.ndarray) else jnp.asarray(a, jnp.int32)


def _number(x: Any) -> Any:
    """A Python number as the float64 NumPy scalar a scene file gives (JIT sees one type, not a weak one)."""
    return np.float64(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else x


def _canonical_params(params: shading.Params) -> shading.Params:
    """The same leaves without names and other static metadata (one compiled kernel for all pigments).

    Python numbers become NumPy float64 scalars, as loaded scenes hold: `replace(params, gain=0.3)`
    reuses the compiled kernel instead of compiling another for a weakly typed (or integer) leaf.
    """
    params = jax.tree.map(_number, params)
    return shading.Params(
        wash=Pigment(K=params.wash.K, S=params.wash.S),
        unlit=Pigment(K=params.unlit.K, S=params.unlit.S),
        paper=params.paper,
        light=params.light,
        k_wash=params.k_wash,
        k_specular=params.k_specular,
        shininess=params.shininess,
        k_unlit=params.k_unlit,
        gain=params.gain,
        bias=params.bias,
        wash_reduction=params.wash_reduction,
    )


class Surface(eqx.Module):
    """The geometry shading needs at the covered pixels: what stays fixed while only `Params` change.

    Per-pixel shading keeps each pixel's unit normal `N` (turned towards the eye
    on drawn back faces) and unit direction to the eye `V`; per-vertex shading
    keeps the vertices' normals and eye directions and, per pixel, its triangle,
    barycentrics and whether the triangle is a drawn back face (`flip`). The
    fitters compute it once and shade it at every step.
    """

    N: Any = None
    V: Any = None
    vertex_N: Any = None
    vertex_V: Any = None
    faces: Any = None
    tri: Any = None
    bary: Any = None
    flip: Any = None
    mode: str = eqx.field(static=True, default="per-pixel")


def surface(vertices, faces, normals, camera, vis, both, *, width, height, mode) -> tuple[Surface, Array]:
    """The `Surface` at the covered pixels `vis.pixels`, and the clip-space vertices.

    Differentiable in `vertices`, `normals` and `camera`. `both` (a bool, may be
    traced) says whether back faces are drawn; back-facing triangles are then
    shaded with their normals reversed (OpenGL's two-sided lighting).
    """
    dtype = jnp.result_type(vertices, float)
    clip = clip_positions(vertices, camera.view_projection(width / height))
    eye = jnp.asarray(camera.eye, dtype)
    tri, pixels = vis.pixel_tri, vis.pixels
    bary, front = barycentrics(clip, faces, tri, pixels, width, height)
    flip = both & ~front  # a back face, drawn: turn its normal towards the eye
    if mode == "per-pixel":
        N = shading.safe_normalize(interpolate(normals, faces, tri, bary))
        N = jnp.where(flip[:, None], -N, N)
        V = shading.safe_normalize(eye - interpolate(vertices, faces, tri, bary))
        return Surface(N=N, V=V, mode=mode), clip
    V = shading.safe_normalize(eye - vertices)
    return Surface(vertex_N=normals, vertex_V=V, faces=faces, tri=tri, bary=bary, flip=flip, mode=mode), clip


def surface_thicknesses(surf: Surface, params: shading.Params) -> tuple[Array, Array]:
    """Wash and unlit thickness at the surface's pixels, per pixel or per vertex (then interpolated)."""
    L = shading.safe_normalize(jnp.asarray(params.light))
    if surf.mode == "per-pixel":
        return shading.thicknesses(surf.N, L, surf.V, params)
    front_v = jnp.stack(shading.thicknesses(surf.vertex_N, L, surf.vertex_V, params), axis=1)  # (V, 2)
    back_v = jnp.stack(shading.thicknesses(-surf.vertex_N, L, surf.vertex_V, params), axis=1)
    thick = jnp.where(
        surf.flip[:, None],
        interpolate(back_v, surf.faces, surf.tri, surf.bary),
        interpolate(front_v, surf.faces, surf.tri, surf.bary),
    )
    return thick[:, 0], thick[:, 1]


def _shade(vertices, faces, normals, camera, params, vis, both, *, width, height, mode):
    """Linear RGB of the covered pixels `vis.pixels`: (P, 3), and the clip-space vertices."""
    surf, clip = surface(vertices, faces, normals, camera, vis, both, width=width, height=height, mode=mode)
    wash, unlit = surface_thicknesses(surf, params)
    return shading.glaze(params, wash, unlit), clip


@functools.partial(jax.jit, static_argnames=("width", "height", "mode", "antialias"))
def _render_kernel(vertices, faces, normals, camera, params, vis, both, *, width, height, mode, antialias):
    """(H, W, 4): linear RGB and coverage."""
    rgb, clip = _shade(vertices, faces, normals, camera, params, vis, both, width=width, height=height, mode=mode)
    n = width * height
    paper = jnp.broadcast_to(jnp.asarray(params.paper, rgb.dtype), (n, 3))
    image = paper.at[vis.pixels].set(rgb, mode="drop", unique_indices=True)
    cover = jnp.zeros((n, 1), rgb.dtype).at[vis.pixels].set(1, mode="drop", unique_indices=True)
    image = jnp.concatenate([image, cover], axis=1)
    if antialias:
        from ._antialias import antialias as _antialias

        image = _antialias(image, clip, faces, vis.silhouettes, width, height)
    return image.reshape(height, width, 4)


def _kernel_args(scene, params, vis) -> tuple:
    """The kernels' traced arguments: geometry, camera, canonical params, visibility, back faces drawn."""
    mesh = scene.mesh
    both = np.bool_(not scene.cull_backfaces)
    return mesh.vertices, _int32(mesh.faces), mesh.normals, scene.camera, _canonical_params(params), vis, both


def _kernel_statics(scene) -> dict:
    return {"width": scene.width, "height": scene.height, "mode": scene.shading}


def _render(scene, params, visibility, antialias, alpha):
    if params is None:
        params = scene.params
    vis = _visibility(scene, visibility, antialias)
    rgba = _render_kernel(*_kernel_args(scene, params, vis), **_kernel_statics(scene), antialias=bool(antialias))
    # One compiled kernel serves both: the slice is free under jit, a small copy otherwise.
    return rgba if alpha else rgba[..., :3]


def render(
    scene: Any,
    params: shading.Params | None = None,
    *,
    visibility: Visibility | None = None,
    antialias: bool = False,
) -> Float[Array, "H W 3"]:
    """Render a scene as a watercolour: linear RGB, differentiable.

    **Arguments:**

    - `scene`: a `Scene` (`load_scene`). Its vertices and camera fields are
      differentiable leaves; `scene.shading` picks per-pixel or per-vertex
      shading.
    - `params`: the shading parameters (pigments, paper, light, constants), a
      `shading.Params` pytree; defaults to `scene.params`. `jax.grad`,
      `jax.jacfwd` and optimistix work through it directly.
    - `visibility`: a `Visibility` from `rasterize(scene)` to reuse. By default
      it is computed once per geometry, camera and size and cached (for
      concrete scenes); when the geometry is traced (e.g. differentiated
      without a given visibility) it is computed by a host callback.
    - `antialias`: blend pixels along silhouette edges by the edges' analytic
      positions (nvdiffrast's antialiasing), which also gives gradients with
      respect to vertex positions and the camera. Off by default: it costs
      a silhouette analysis per visibility and a little per render.

    **Returns:**

    (H, W, 3) linear RGB reflectance; row 0 is the top of the image.
    Uncovered pixels show the paper (`params.paper`).
    """
    return _render(scene, params, visibility, antialias, alpha=False)


def render_rgba(
    scene: Any,
    params: shading.Params | None = None,
    *,
    visibility: Visibility | None = None,
    antialias: bool = False,
) -> Float[Array, "H W 4"]:
    """`render` with the coverage (alpha) as a fourth channel.

    Alpha is 1 where a triangle covers the pixel centre and 0 elsewhere, or the
    antialiased coverage with `antialias=True`. The colour channels are the
    same as `render`'s (the paper shows where alpha is 0).
    """
    return _render(scene, params, visibility, antialias, alpha=True)


@functools.partial(jax.jit, static_argnames=("width", "height", "mode"))
def _thickness_kernel(vertices, faces, normals, camera, params, vis, both, *, width, height, mode):
    surf, _ = surface(vertices, faces, normals, camera, vis, both, width=width, height=height, mode=mode)
    wash, unlit = surface_thicknesses(surf, params)
    maps = jnp.zeros((width * height, 2), wash.dtype)
    maps = maps.at[vis.pixels].set(jnp.stack([wash, unlit], axis=1), mode="drop", unique_indices=True)
    return maps.reshape(height, width, 2)


def render_thicknesses(
    scene: Any,
    params: shading.Params | None = None,
    *,
    visibility: Visibility | None = None,
) -> Float[Array, "H W 2"]:
    """The wash and unlit thickness maps `render` glazes: (H, W, 2), 0 where uncovered.

    The model's intermediate result (what the seed's shader uses as LUT
    coordinates), for inspection and for sensitivity studies; differentiable
    like `render`. Arguments as `render`.
    """
    if params is None:
        params = scene.params
    vis = _visibility(scene, visibility, False)
    return _thickness_kernel(*_kernel_args(scene, params, vis), **_kernel_statics(scene))
