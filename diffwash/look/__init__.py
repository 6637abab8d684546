"""The watercolour look (issue 13): paper, edges, unevenness, brush strokes, hatching, shadows, pigment mixes.

The seed's future work, as array operators in JAX with a GLSL twin of each,
generated here from the same constants (docs/watercolour.md):

- `_textures`: the screen-space tile (paper height and shading, turbulence and
  dispersion noises), procedural or from an image;
- `_paper`: granulation and staining (Curtis et al. 1997), density,
  unevenness (Bousseau et al. 2006), paper shading;
- `_edges`: edge darkening (a separable, fixed-radius blur at reduced
  resolution);
- `_strokes`: the brush-stroke layer, LIC of solid noise along principal
  curvature directions (Lum and Ma 2001), a per-vertex attribute;
- `_hatching`: a tonal art map (Praun et al. 2001) for a pen-and-wash unlit
  glaze;
- `_shadow`: a shadow map and percentage-closer lookups for self-shadowing;
- `_mix`: pigment mixes across a surface and their 3D LUT;
- `_look`: the `Look` parameters and the pipeline (`surface_terms`,
  `image_terms`, `compose`) with its GLSL passes.
"""

import lazy_loader as _lazy

# The names of `__init__.pyi`, each imported from its module when first used.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
