"""The watercolour look (issue 13): paper, edges, unevenness, brush strokes, hatching, shadows, pigment mixes.

The seed's future work, as array operators (docs/watercolour.md). Each
effect's per-pixel arithmetic is written once, against the array namespace of
`diffwash._xp`: JAX runs it, and `diffwash._look_glsl` traces it into the
look's shaders (the real-time host code, OpenGL included, lives outside this
package, so importing it needs no OpenGL):

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
- `_look`: the `Look` parameters, each declared once with its scene key
  (`leaf_specs`), and the pipeline (`surface_terms`, `pixel_terms`,
  `image_terms`, `compose`).
"""

import lazy_loader as _lazy

# The names of `__init__.pyi`, each imported from its module when first used.
__getattr__, __dir__, __all__ = _lazy.attach_stub(__name__, __file__)
