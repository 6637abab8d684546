r"""The renderer: rasterize -> interpolate -> shading -> Kubelka-Munk glazes -> antialias -> image.

`render(scene, params)` composes the array ops of this package (after
nvdiffrast's) with the watercolour model of `diffwash.shading`:

1. `rasterize` (`diffwash._rasterize`; not differentiable): the triangle seen
   at each pixel, on the device; compacted to the covered pixels (`covered`).
2. `barycentrics` and `interpolate` (`diffwash._interpolate`; differentiable in
   vertices, attributes and camera): perspective-correct barycentrics of the
   covered pixel centres, and attributes there.
3. Shading, per pixel or per vertex (Smedresman's two variants):

   - *per-pixel*: the normal (renormalised) and the position are interpolated;
     `V = normalize(eye - P)`; `shading.thicknesses(N, L, V)` at each pixel.
   - *per-vertex*: `shading.thicknesses` at the vertices (`V = normalize(eye -
     vertex)`), interpolated perspective-correctly.

   In both the Kubelka-Munk glazes (`shading.glaze`, `diffwash.km`) are
   evaluated per pixel, per band (the three sRGB channels, or a spectral
   library's wavelengths, then seen as linear sRGB: `shading.colour`). Where back faces are drawn (open meshes), a
   back-facing triangle is shaded with its normals turned towards the eye
   (OpenGL's two-sided lighting).
4. Uncovered pixels show the bare paper.
5. Optionally `antialias` (`diffwash._antialias`; differentiable): silhouette
   edges blend neighbouring pixels by the edge's analytic position, giving
   gradients with respect to vertex positions and camera.

Steps 1 and the choice of silhouette pairs make up a `Visibility`: computed on
the device, reused while the geometry, the camera and the size stay fixed
(passed in, or cached by the arrays' identity — JAX arrays — or content —
NumPy arrays — never by copying device arrays to the host). Only covered pixels
are shaded (a compacted list, padded to a bucket size), so the cost follows the
object's area on screen, not the image's.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
from collections.abc import Iterator
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from . import _watercolour, shading
from ._antialias import Silhouettes, silhouettes
from ._antialias import antialias as antialias_image
from ._cache import LRU, same_arrays
from ._errors import DiffwashError
from ._camera import Camera
from ._interpolate import barycentrics, interpolate
from ._rasterize import clip_positions, covered, is_concrete, rasterize as rasterize_op

if TYPE_CHECKING:  # annotations only: scenes are built above this module (diffwash._scene imports it)
    from ._scene import Scene

__all__ = [
    "Visibility",
    "Surface",
    "rasterize",
    "visibility",
    "render",
    "render_rgba",
    "render_thicknesses",
    "render_views",
    "render_strips",
    "surface",
    "surface_thicknesses",
    "clear_visibility_cache",
]

_cache = LRU(4)
#: The shadow maps' triangles (the light's depth pass) of concrete meshes and lights.
_light_cache = LRU(4)


class Visibility(eqx.Module):
    """What each pixel sees: the rasterizer's output, ready for shading.

    Non-differentiable and reusable while the geometry, the camera and the
    image size stay fixed.

    **Fields:**

    - `tri_id`: (H, W) int32, the triangle seen at each pixel centre (an index
      into `mesh.faces`), -1 where no triangle covers it.
    - `depth`: (H, W), eye-space depth of the visible surface (distance
      along the view axis), `inf` where uncovered.
    - `pixels`: (P,) int32, row-major indices of the covered pixels, padded to a
      bucket size with `H * W` (an index past the image).
    - `pixel_tri`: (P,) int32, the triangle at each of `pixels` (padding repeats
      a real covered pixel's triangle, so padded entries shade something valid).
    - `silhouettes`: the antialiasing work items (`diffwash._antialias.Silhouettes`),
      or None when not prepared.
    - `complete`: False when the rasterizer's fragment budget was too small.
    - `width`, `height`: image size in pixels.
    """

    tri_id: Int[Array, "H W"]
    depth: Float[Array, "H W"]
    pixels: Int[Array, " P"]
    pixel_tri: Int[Array, " P"]
    silhouettes: Silhouettes | None = None
    complete: Bool[ArrayLike, ""] = True
    width: int = eqx.field(static=True, default=0)
    height: int = eqx.field(static=True, default=0)

    @property
    def coverage(self) -> Bool[Array, "H W"]:
        """(H, W) bool: which pixel centres some triangle covers."""
        return self.tri_id >= 0


def clear_visibility_cache() -> None:
    """Forget the visibilities (and the look's shadow-map passes) `render` computed for concrete scenes."""
    _cache.clear()
    _light_cache.clear()


@functools.partial(jax.jit, static_argnames=("aspect",))
def _clip(vertices, camera, aspect):
    """Clip-space vertices, compiled (no op-by-op dispatch when called on concrete arrays)."""
    return clip_positions(vertices, camera.view_projection(aspect))


def visibility(
    vertices: Float[ArrayLike, "V 3"],
    faces: Int[ArrayLike, "F 3"],
    camera: Camera,
    *,
    width: int,
    height: int,
    cull_backfaces: bool,
    antialias: bool = False,
    capacity: int | None = None,
    topology: tuple[Array, Array] | None = None,
) -> Visibility:
    """The `Visibility` of a mesh seen by a camera: rasterize, compact, and (optionally) find silhouettes.

    Runs on the device; under `jax.jit` or `jax.vmap` (geometry or camera
    traced) the compacted lists have their largest sizes (every pixel; two
    pairs per pixel) and the rasterizer its default fragment budget
    (`capacity`). Pass `topology` (`diffwash.ops.edge_topology(faces)`) for
    antialiasing when `faces` is traced.
    """
    clip = _clip(vertices, camera, width / height)
    raster = rasterize_op(clip, faces, (height, width), cull_backfaces=cull_backfaces, capacity=capacity)
    pixels, pixel_tri = covered(raster.tri_id)
    sil = None
    if antialias:
        sil = silhouettes(clip, faces, raster.tri_id, raster.depth, cull_backfaces=cull_backfaces, topology=topology)
    return Visibility(
        tri_id=raster.tri_id,
        depth=raster.depth,
        pixels=pixels,
        pixel_tri=pixel_tri,
        silhouettes=sil,
        complete=raster.complete,
        width=width,
        height=height,
    )


def _scene_visibility(scene, *, antialias: bool) -> Visibility:
    if is_concrete(_geometry(scene)):
        # Concrete geometry inside a traced function (a jitted loss closing over the scene): compute the
        # visibility now, on the values, rather than staging it into the caller's trace.
        with jax.ensure_compile_time_eval():
            return _concrete_visibility(scene, antialias=antialias)
    return _concrete_visibility(scene, antialias=antialias)


def _concrete_visibility(scene, *, antialias: bool) -> Visibility:
    vis = visibility(
        scene.mesh.vertices,
        scene.mesh.faces,
        scene.camera,
        width=scene.width,
        height=scene.height,
        cull_backfaces=scene.cull_backfaces,
        antialias=antialias,
    )
    if is_concrete(vis) and not bool(vis.complete):  # pragma: no cover - the exact budget is always enough
        raise RuntimeError("the rasterizer's fragment budget was too small")
    return vis


def rasterize(scene: Scene, *, antialias: bool = False) -> Visibility:
    """Which triangle each pixel of `scene`'s image sees, on the device.

    **Arguments:**

    - `scene`: a `Scene` (its mesh, camera, size and back-face mode are used).
      Works with concrete and traced geometry alike (under `jax.jit`, the
      lists have their largest sizes).
    - `antialias`: also prepare the silhouette work items that
      `render(..., antialias=True)` needs.

    **Returns:**

    A `Visibility`, reusable while geometry, camera and size stay fixed.
    """
    return _scene_visibility(scene, antialias=antialias)


def _geometry(scene) -> tuple:
    return (scene.mesh.vertices, scene.mesh.faces, scene.camera)


def _with_silhouettes(scene, vis: Visibility) -> Visibility:
    """`vis` with its antialiasing work items (computed now when the scene and `vis` are concrete)."""
    with jax.ensure_compile_time_eval() if is_concrete(_geometry(scene), vis) else contextlib.nullcontext():
        clip = _clip(scene.mesh.vertices, scene.camera, scene.width / scene.height)
        sil = silhouettes(clip, scene.mesh.faces, vis.tri_id, vis.depth, cull_backfaces=scene.cull_backfaces)
    return eqx.tree_at(lambda v: v.silhouettes, vis, sil, is_leaf=lambda x: x is None)


def _visibility_for(scene, given: Visibility | None, antialias: bool) -> Visibility:
    """The scene's visibility: given, cached (concrete geometry), or computed on the device."""
    if given is not None:
        if (given.width, given.height) != (scene.width, scene.height):
            raise ValueError(
                f"visibility is for a {given.width}x{given.height} image, the scene is {scene.width}x{scene.height}"
            )
        return _with_silhouettes(scene, given) if antialias and given.silhouettes is None else given
    if not is_concrete(_geometry(scene)):
        return _scene_visibility(scene, antialias=antialias)
    extra = (scene.width, scene.height, scene.cull_backfaces)
    vis = _cache.get(_geometry(scene), lambda: _scene_visibility(scene, antialias=antialias), extra=extra)
    if antialias and vis.silhouettes is None:
        vis = _with_silhouettes(scene, vis)
        _cache.put(_geometry(scene), vis, extra=extra)
    return vis


class Surface(eqx.Module):
    """The geometry shading needs at the covered pixels: what stays fixed while only `Params` change.

    Per-pixel shading keeps each pixel's unit normal `N` (turned towards the eye
    on drawn back faces), unit direction to the eye `V` and barycentrics (for
    other attributes, as the look's); per-vertex shading
    keeps the vertices' normals and eye directions and, per pixel, its triangle,
    barycentrics and whether the triangle is a drawn back face (`flip`). The
    fitters compute it once and shade it at every step.
    """

    N: Float[Array, "P 3"] | None = None
    V: Float[Array, "P 3"] | None = None
    vertex_N: Float[Array, "Vn 3"] | None = None
    vertex_V: Float[Array, "Vn 3"] | None = None
    faces: Int[Array, "F 3"] | None = None
    tri: Int[Array, " P"] | None = None
    bary: Float[Array, "P 3"] | None = None
    flip: Bool[Array, " P"] | None = None
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
        return Surface(N=N, V=V, bary=bary, mode=mode), clip  # bary: for what else is interpolated (the look)
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
    return shading.colour(params, wash, unlit), clip


@functools.partial(jax.jit, static_argnames=("width", "height", "mode", "antialias"))
def _render_kernel(vertices, faces, normals, camera, params, vis, both, *, width, height, mode, antialias):
    """(H, W, 4): linear RGB and coverage."""
    rgb, clip = _shade(vertices, faces, normals, camera, params, vis, both, width=width, height=height, mode=mode)
    n = width * height
    paper = jnp.broadcast_to(jnp.asarray(shading.paper_colour(params), rgb.dtype), (n, rgb.shape[-1]))
    image = paper.at[vis.pixels].set(rgb, mode="drop", unique_indices=True)
    cover = jnp.zeros((n, 1), rgb.dtype).at[vis.pixels].set(1, mode="drop", unique_indices=True)
    image = jnp.concatenate([image, cover], axis=1)
    if antialias:
        image = antialias_image(image, clip, faces, vis.silhouettes, width, height)
    return image.reshape(height, width, -1)



@functools.partial(jax.jit, static_argnames=("width", "height", "mode", "antialias"))
def _look_kernel(vertices, faces, normals, camera, params, vis, both, wc, light_tri, light_depth=None, vertex_shadow=None, *,
                 width, height, mode, antialias):  # fmt: skip
    """(H, W, 4): the watercolour look's linear RGB (`diffwash._watercolour.look_image`) and coverage.

    `light_depth`: the shadow map when the light and the mesh are fixed (computed once, outside), else
    None: computed here, differentiable in both. `vertex_shadow`: the shadow factor at the vertices when the
    shadow's bias and normals are fixed too (computed once, outside), else None.
    """
    surf, clip = surface(vertices, faces, normals, camera, vis, both, width=width, height=height, mode=mode)
    wash, unlit = surface_thicknesses(surf, params)
    rgb = _watercolour.look_image(surf, clip, wash, unlit, vertices, faces, normals, camera, params, vis, wc, light_tri,
                                  light_depth, vertex_shadow, width=width, height=height)  # fmt: skip
    cover = jnp.zeros((width * height, 1), rgb.dtype).at[vis.pixels].set(1, mode="drop", unique_indices=True)
    image = jnp.concatenate([rgb, cover], axis=1)
    if antialias:
        image = antialias_image(image, clip, faces, vis.silhouettes, width, height)
    return image.reshape(height, width, -1)


def _render_look(scene, params, visibility, antialias):
    """The scene's watercolour look: the light's depth pass (when it has shadows), then `_look_kernel`."""
    vis = _visibility_for(scene, visibility, antialias)
    wc = scene.watercolour
    light_tri = depth = shadow = None
    if wc.shadow:
        light = params.light if is_concrete(params.light) else scene.params.light  # the depth pass is a step
        geometry = (scene.mesh.vertices, scene.mesh.faces, light)

        def compute():  # the depth pass and its shadow map, evaluated now even under a trace (constants)
            with jax.ensure_compile_time_eval():
                tri = _watercolour.shadow_triangles(*geometry)
                return tri, _watercolour.shadow_depth(*geometry, tri)

        if is_concrete(geometry):
            light_tri, depth = _light_cache.get(geometry, compute)
            if not is_concrete(params.light):
                depth = None  # a traced light: the map is computed in the kernel, differentiable in it
        else:
            light_tri = _watercolour.shadow_triangles(*geometry)
        fixed = (*geometry, scene.mesh.normals, wc.look.shadow_bias)
        if depth is not None and is_concrete(fixed):  # the lookups at the vertices are constants too: once
            with jax.ensure_compile_time_eval():
                shadow = _light_cache.get(fixed, lambda: _watercolour.fixed_vertex_shadow(*fixed, light_tri, depth), extra="vertices")
    args = _kernel_args(scene, params, vis)
    return _look_kernel(*args, wc, light_tri, depth, shadow, **_kernel_statics(scene), antialias=bool(antialias))


def _int32(a):
    return a.astype(np.int32, copy=False) if isinstance(a, np.ndarray) else jnp.asarray(a, jnp.int32)


def _kernel_args(scene, params, vis) -> tuple:
    """The kernels' traced arguments: geometry, camera, canonical params, visibility, back faces drawn."""
    mesh = scene.mesh
    both = np.bool_(not scene.cull_backfaces)
    return mesh.vertices, _int32(mesh.faces), mesh.normals, scene.camera, shading.canonical(params), vis, both


def _kernel_statics(scene) -> dict:
    return {"width": scene.width, "height": scene.height, "mode": scene.shading}


def _render(scene, params, visibility, antialias, alpha):
    if params is None:
        params = scene.params
    if getattr(scene, "watercolour", None) is not None:  # the look's edge blur needs the whole image: no strips
        with same_arrays():  # the mesh's arrays key the visibility and the light pass: hash them once
            rgba = _render_look(scene, params, visibility, antialias)
        return rgba if alpha else rgba[..., :-1]
    if visibility is None and scene.width * scene.height > TILE_PIXELS and is_concrete(_geometry(scene)):
        return jnp.concatenate([s for _, s in render_strips(scene, params, antialias=antialias, alpha=alpha)])
    vis = _visibility_for(scene, visibility, antialias)
    rgba = _render_kernel(*_kernel_args(scene, params, vis), **_kernel_statics(scene), antialias=bool(antialias))
    # One compiled kernel serves both: the slice is free under jit, a small copy otherwise.
    return rgba if alpha else rgba[..., :-1]


def render(
    scene: Scene,
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
      without a given visibility) it is computed on the device in the trace.
    - `antialias`: blend pixels along silhouette edges by the edges' analytic
      positions (nvdiffrast's antialiasing), which also gives gradients with
      respect to vertex positions and the camera. Off by default: it costs
      a silhouette analysis per visibility and a little per render.

    **Returns:**

    (H, W, 3) linear RGB reflectance; row 0 is the top of the image.
    Uncovered pixels show the paper (`params.paper`, seen as linear sRGB). Images of more than
    `TILE_PIXELS` pixels (concrete geometry, no `visibility` given) are drawn
    in strips (`render_strips`), which bounds the memory the rasterizer and
    the shading take.
    """
    return _render(scene, params, visibility, antialias, alpha=False)


def render_rgba(
    scene: Scene,
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
    scene: Scene,
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
    vis = _visibility_for(scene, visibility, False)
    return _thickness_kernel(*_kernel_args(scene, params, vis), **_kernel_statics(scene))


def _stack_visibilities(vis: list[Visibility]) -> Visibility:
    """Visibilities of one image size padded to common lengths and stacked on a leading axis (for `vmap`)."""
    n = vis[0].width * vis[0].height

    def pad(x: Array, size: int, fill: int) -> Array:
        return jnp.concatenate([x, jnp.full(size - x.shape[0], fill, x.dtype)])

    p = max(v.pixels.shape[0] for v in vis)
    padded = [
        eqx.tree_at(lambda v: (v.pixels, v.pixel_tri), v, (pad(v.pixels, p, n), pad(v.pixel_tri, p, 0))) for v in vis
    ]
    if all(v.silhouettes is not None for v in vis):
        m = max(v.silhouettes.a.shape[0] for v in vis)
        padded = [
            eqx.tree_at(
                lambda v: v.silhouettes,
                v,
                Silhouettes(*(pad(x, m, f) for x, f in zip(
                    (v.silhouettes.a, v.silhouettes.b, v.silhouettes.tri, v.silhouettes.edge), (n, n, 0, 0)))),
            )
            for v in padded
        ]  # fmt: skip
    return jax.tree.map(lambda *x: jnp.stack([jnp.asarray(a) for a in x]), *padded)


def render_views(
    scene: Scene,
    cameras: Camera | list[Camera],
    params: shading.Params | None = None,
    *,
    antialias: bool = False,
) -> Float[Array, "N H W 3"]:
    """Render the scene from several cameras in one `jax.vmap`ped program.

    **Arguments:**

    - `scene`: the `Scene` (its mesh, size, shading mode and back faces).
    - `cameras`: a list of `Camera`s, or one `Camera` whose leaves have a
      leading axis of views.
    - `params`: shading parameters shared by the views (default: the scene's).
    - `antialias`: as `render`.

    **Returns:**

    (N, H, W, 3) linear RGB, differentiable like `render`. With concrete
    cameras each view's visibility is computed (and cached) as `render` does;
    with traced ones it is computed in the trace, on the device.
    """
    if isinstance(cameras, (list, tuple)):
        cameras = jax.tree.map(lambda *x: jnp.stack([jnp.asarray(a) for a in x]), *cameras)
    params = scene.params if params is None else params
    n_views = jax.tree_util.tree_leaves(cameras)[0].shape[0]
    if not is_concrete(cameras, scene.mesh.vertices):
        return jax.vmap(lambda c: render(dataclasses.replace(scene, camera=c), params, antialias=antialias))(cameras)
    views = [dataclasses.replace(scene, camera=jax.tree.map(lambda x: x[i], cameras)) for i in range(n_views)]
    vis = _stack_visibilities([_visibility_for(v, None, antialias) for v in views])
    vertices, faces, normals, _, p, _, both = _kernel_args(scene, params, vis)
    kernel = functools.partial(_render_kernel, **_kernel_statics(scene), antialias=bool(antialias))
    images = jax.vmap(kernel, in_axes=(None, None, None, 0, None, 0, None))(vertices, faces, normals, cameras, p, vis, both)
    return images[..., :-1]


#: Images of more pixels than this render in horizontal strips, so that memory stays bounded.
TILE_PIXELS = 1 << 22
#: The most pixels `render_strips` draws with a watercolour look, which blurs across the whole image and so
#: renders it in one piece: 1920x1080 fits; about 2 GB of memory at this size (3 GB at 2048x2048).
LOOK_MAX_PIXELS = 1 << 21


def _check_look_size(scene: Scene) -> None:
    """Refuse a look image too big to draw in one piece, naming a size of the same shape that fits."""
    n = scene.width * scene.height
    if n <= LOOK_MAX_PIXELS:
        return
    k = (LOOK_MAX_PIXELS / n) ** 0.5
    fits = f"{max(1, int(scene.width * k))}x{max(1, int(scene.height * k))}"
    raise DiffwashError(
        f"the watercolour look draws the whole image at once and {scene.width}x{scene.height} = {n:,} pixels is over "
        f"its limit of {LOOK_MAX_PIXELS:,} (about 2 GB of memory): render at {fits}, or without the scene's "
        f"\"watercolour\" object (then in strips, at any size)",
        file=getattr(scene, "path", None),
        field="image",
    )


class _Window(eqx.Module):
    """A camera seen through a window of its image: rows `[start, start + rows)` of `height` become a whole image.

    Duck-types `Camera` for the renderer: `eye` is the camera's, and
    `view_projection` maps the window onto clip space (`y' = s y + t w`), so
    a strip renders exactly the pixels it covers in the full image.
    """

    camera: Camera
    crop: Float[Array, "4 4"]
    aspect: float = eqx.field(static=True)

    @property
    def eye(self):
        return self.camera.eye

    def view_projection(self, aspect: float) -> Float[Array, "4 4"]:
        return self.crop @ self.camera.view_projection(self.aspect)


def _window(scene, start: int, rows: int):
    s = scene.height / rows
    crop = np.eye(4)
    crop[1, 1], crop[1, 3] = s, 1 - s + 2 * start / rows
    cam = _Window(camera=scene.camera, crop=jnp.asarray(crop, jnp.result_type(float)), aspect=scene.width / scene.height)
    return dataclasses.replace(scene, camera=cam, height=rows)


def render_strips(
    scene: Scene,
    params: shading.Params | None = None,
    *,
    antialias: bool = False,
    alpha: bool = False,
    rows: int | None = None,
) -> Iterator[tuple[int, Float[Array, "h W C"]]]:
    """Render the image in horizontal strips, one at a time: bounded memory for any image size.

    **Arguments:** as `render`; `alpha` adds the coverage channel; `rows`: rows
    per strip (default: about `TILE_PIXELS` pixels per strip).

    **Yields:**

    `(first_row, strip)`: consecutive strips, together the image `render`
    (or `render_rgba`) draws. Each strip is rendered with its own visibility,
    from a window of the camera's image with a one-row margin where
    antialiasing needs the neighbours. A scene with a watercolour look is one
    strip (the look's edge darkening blurs across the whole image).
    """
    if getattr(scene, "watercolour", None) is not None:
        _check_look_size(scene)
        yield 0, _render(scene, params, None, antialias, alpha)
        return
    rows = max(1, TILE_PIXELS // scene.width) if rows is None else int(rows)
    halo = 1 if antialias else 0
    window = min(scene.height, rows + 2 * halo)
    for r0 in range(0, scene.height, rows):
        r1 = min(r0 + rows, scene.height)
        start = min(max(r0 - halo, 0), scene.height - window)
        tile = _window(scene, start, window)
        vis = _concrete_visibility(tile, antialias=antialias)
        yield r0, _render(tile, params, vis, antialias, alpha)[r0 - start : r1 - start]
