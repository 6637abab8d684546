"""The renderer's array ops, after nvdiffrast's: what `diffwash.render` composes.

Each takes explicit arrays and returns explicit values, runs on the device, and
works under `jax.jit` and `jax.vmap`:

- `rasterize(clip, faces, (H, W))` -> `Raster` (triangle ids and depths; not
  differentiable), `covered(tri_id)` (the covered pixels, compacted), and
  `clip_positions(vertices, view_projection)`;
- `barycentrics(clip, faces, tri, pixels, W, H)` and
  `interpolate(attr, faces, tri, bary)` (differentiable);
- the watercolour model: `diffwash.shading` (thicknesses, glazes) over
  `diffwash.km` (Kubelka-Munk layers and compositing);
- `silhouettes(clip, faces, tri_id, depth, ...)` (which pixel pairs a
  silhouette splits; not differentiable) and
  `antialias(image, clip, faces, silhouettes, W, H)` (differentiable in the
  image and the geometry), with `edge_topology(faces)` (per mesh).

A user composes them into any shading model; `diffwash.render` is one such
composition.
"""

from ._antialias import Silhouettes as Silhouettes
from ._antialias import antialias as antialias
from ._antialias import edge_topology as edge_topology
from ._antialias import silhouettes as silhouettes
from ._interpolate import barycentrics as barycentrics
from ._interpolate import interpolate as interpolate
from ._rasterize import Raster as Raster
from ._rasterize import clip_positions as clip_positions
from ._rasterize import covered as covered
from ._rasterize import default_capacity as default_capacity
from ._rasterize import rasterize as rasterize
from ._rasterize import required_capacity as required_capacity
