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

__all__ = ["render", "render_rgba", "clear_visibility_cache"]

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


def _scene_key(scene: Any, antialias: bool) -> tuple:
    cam = scene.camera
    camera = tuple(np.asarray(getattr(cam, f), np.float64).tobytes() for f in ("eye", "target", "up", "fov_y", "near", "far"))
    return (
        scene.width,
        scene.height,
        scene.cull_backfaces,
        antialias,
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
    key = _scene_key(scene, antialias)
    vis = _cache.get(key)
    if vis is None:
        vis = rasterize(scene, antialias=antialias)
        _cache[key] = vis
        while len(_cache) > _CACHE_SIZE:
            _cache.popitem(last=False)
    else:
        _cache.move_to_end(key)
    return vis


def _int32(a: Any) -> Any:
    return a.astype(np.int32, copy=False) if isinstance(a, np.ndarray) else jnp.asarray(a, jnp.int32)


def _canonical_params(params: shading.Params) -> shading.Params:
    """The same leaves without names and other static metadata (one compiled kernel for all pigments)."""
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


def _shade(vertices, faces, normals, camera, params, vis, *, width, height, mode, both):
    """Linear RGB of the covered pixels `vis.pixels`: (P, 3)."""
    dtype = jnp.result_type(vertices, float)
    clip = clip_positions(vertices, camera.view_projection(width / height))
    tri = vis.pixel_tri
    bary, front = barycentrics(clip, faces, tri, vis.pixels, width, height)
    L = shading.safe_normalize(jnp.asarray(params.light, dtype))
    eye = jnp.asarray(camera.eye, dtype)
    if mode == "per-pixel":
        N = shading.safe_normalize(interpolate(normals, faces, tri, bary))
        if both:
            N = jnp.where(front[:, None], N, -N)
        P = interpolate(vertices, faces, tri, bary)
        V = shading.safe_normalize(eye - P)
        wash, unlit = shading.thicknesses(N, L, V[:, :], params)
    else:
        V = shading.safe_normalize(eye - vertices)
        wash_v, unlit_v = shading.thicknesses(normals, L, V, params)
        wash = interpolate(wash_v, faces, tri, bary)
        unlit = interpolate(unlit_v, faces, tri, bary)
        if both:
            wash_b, unlit_b = shading.thicknesses(-normals, L, V, params)
            wash = jnp.where(front, wash, interpolate(wash_b, faces, tri, bary))
            unlit = jnp.where(front, unlit, interpolate(unlit_b, faces, tri, bary))
    return shading.glaze(params, wash, unlit), clip


@functools.partial(jax.jit, static_argnames=("width", "height", "mode", "both", "antialias", "alpha"))
def _render_kernel(vertices, faces, normals, camera, params, vis, *, width, height, mode, both, antialias, alpha):
    rgb, clip = _shade(vertices, faces, normals, camera, params, vis, width=width, height=height, mode=mode, both=both)
    n = width * height
    paper = jnp.broadcast_to(jnp.asarray(params.paper, rgb.dtype), (n, 3))
    image = paper.at[vis.pixels].set(rgb, mode="drop", unique_indices=True)
    if alpha or antialias:
        cover = jnp.zeros((n, 1), rgb.dtype).at[vis.pixels].set(1, mode="drop", unique_indices=True)
        image = jnp.concatenate([image, cover], axis=1)
    if antialias:
        from ._antialias import antialias as _antialias

        image = _antialias(image, clip, faces, vis.silhouettes, width, height)
    if not alpha and image.shape[1] == 4:
        image = image[:, :3]
    return image.reshape(height, width, image.shape[1])


def _render(scene, params, visibility, antialias, alpha):
    if params is None:
        params = scene.params
    vis = _visibility(scene, visibility, antialias)
    mesh = scene.mesh
    return _render_kernel(
        mesh.vertices,
        _int32(mesh.faces),
        mesh.normals,
        scene.camera,
        _canonical_params(params),
        vis,
        width=scene.width,
        height=scene.height,
        mode=scene.shading,
        both=not scene.cull_backfaces,
        antialias=bool(antialias),
        alpha=alpha,
    )


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
