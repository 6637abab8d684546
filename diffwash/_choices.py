"""The model's named choices, as plain data that imports nothing.

They are the model's own (`diffwash.shading` re-exports `SHADING_MODES`, and the renderer, the
scene reader and the shader generator take it from there); they are declared in this leaf, below every
module that imports JAX, so that the command line can offer them in `--help` without loading the
numerical stack.
"""

from __future__ import annotations

__all__ = ["SHADING_MODES", "EXPORT_TARGETS", "BLENDER_LEAVES_OUT", "LUT_FORMATS", "SOLVERS", "IMAGE_LOSSES"]

#: Where the wash and unlit thicknesses are computed: at every pixel, or at the vertices and interpolated.
SHADING_MODES = ("per-pixel", "per-vertex")

#: What `diffwash export --target` writes for: the shader language of the .vert/.frag files (GLSL 3.30, WebGL2),
#: a three.js module and page, or a Blender scene (a script, its data, a .blend where `bpy` is installed).
EXPORT_TARGETS = ("webgl2", "glsl330", "threejs", "blender")

#: The watercolour look's effects the Blender target cannot draw, and why: each needs more than the pixel's own
#: values, which is all a shader node sees (`diffwash._blender` carries the look's other effects).
BLENDER_LEAVES_OUT = {
    "edges": "edge darkening needs the glazes' local mean, a blur over the whole image",
    "shadow": "the object's own shadow needs a depth map drawn from the light",
    "hatching": "hatching reads a tonal art map at a level of detail per pixel, from screen-space derivatives",
}

#: LUT file formats (`diffwash.lut.FORMATS`): name -> (file extension, encoding of the stored values).
LUT_FORMATS: dict[str, tuple[str, str]] = {
    "png16": (".png", "srgb"),
    "png8": (".png", "srgb"),
    "exr": (".exr", "linear"),
    "npy": (".npy", "linear"),
}

#: Image-fit solvers by name (`diffwash.fit.SOLVERS`): least-squares solvers work on the residuals,
#: minimisers on half their sum of squares.
SOLVERS = ("lm", "gauss-newton", "dogleg", "bfgs")
#: Where an image fit compares (`diffwash.fit.IMAGE_LOSSES`): linear RGB or CIELAB.
IMAGE_LOSSES = ("linear", "lab")
