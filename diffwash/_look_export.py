"""The watercolour look as an engine runs it: its passes, their shaders for a target, textures and uniforms.

`diffwash.export` of a scene with a `"watercolour"` object writes a `look/`
folder beside the plain model's files; `diffwash._viewer` embeds the same
passes in `viewer.html`. What a host program needs, in the order it draws:

1. `shadow_depth` (once, and again when the light moves): the mesh seen from
   the light into a float depth map (`diffwash._look_glsl.glsl_depth_pass`);
2. `geometry`: the mesh into a float G-buffer `(wash, unlit, mix, stroke)`:
   the model's thicknesses with self-shadowing and hatching
   (`diffwash._look_glsl.geometry_sources`);
3. `edge_downsample`, `edge_rows`, `edge_columns`: the edge blur on a reduced
   grid (`diffwash._look_glsl.glsl_edge_passes`);
4. `final`: edge darkening, strokes, paper, unevenness, the 3D mix LUT and the
   paper's shading, to the screen (`diffwash._look_glsl.glsl_final_pass`).

Every shader is generated from `diffwash.look`'s own functions (traced by
`diffwash._look_glsl`); the inputs (look values, mix LUT, screen tile, tonal art map, per-vertex
mix and stroke layer) are the scene's `Watercolour`'s, as `LookFrame` (the
OpenGL preview) takes them, so the three agree with `diffwash.render`.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._look_glsl import (FULLSCREEN_VERTEX, geometry_sources, glsl_depth_pass, glsl_edge_passes, glsl_final_pass, header,
                         look_frame_uniforms, look_textures)
from .look import SHADOW_MAP_SIZE, edge_downsample

__all__ = ["LOOK_ATTRIBUTES", "LOOK_FOLDER", "LookExport", "look_export", "retarget", "write_look"]

#: The folder of an export that holds the look's passes.
LOOK_FOLDER = "look"
#: The geometry pass's vertex inputs: shader name -> (location, the GLB's attribute).
LOOK_ATTRIBUTES = {"position": (0, "POSITION"), "normal": (1, "NORMAL"), "mix_in": (2, "_MIX"), "stroke_in": (3, "_STROKE")}


@dataclass(frozen=True)
class LookExport:
    """The look's passes for one scene and target.

    **Fields:**

    - `target`: `"webgl2"` or `"glsl330"`.
    - `shaders`: file name -> shader source.
    - `graph`: the pass graph (`passes.json`): render targets, input
      textures, vertex attributes and the passes in drawing order.
    - `textures`: texture name -> its levels (float32 arrays, row 0 first;
      one level but for the mipmapped tonal art map).
    - `uniforms`: every uniform's value (matrices row-major).
    - `attributes`: GLB attribute name -> per-vertex float32 values (`_MIX`, `_STROKE`).
    """

    target: str
    shaders: dict[str, str]
    graph: dict[str, Any]
    textures: dict[str, list[np.ndarray]]
    uniforms: dict[str, Any]
    attributes: dict[str, np.ndarray]


def _shaders(target: str, height: int, hatching: bool) -> dict[str, str]:
    head = header(target)
    depth_vert, depth_frag = glsl_depth_pass()
    geometry_vert, geometry_frag = geometry_sources(target, hatching)
    edges = glsl_edge_passes(edge_downsample(height))
    return {
        "depth.vert": head + depth_vert,
        "depth.frag": head + depth_frag,
        "geometry.vert": geometry_vert,
        "geometry.frag": geometry_frag,
        "fullscreen.vert": head + FULLSCREEN_VERTEX,
        "edge_downsample.frag": head + edges["downsample"],
        "edge_rows.frag": head + edges["blur_rows"],
        "edge_columns.frag": head + edges["blur_columns"],
        "final.frag": head + "#define LOOK_OUTPUT_SRGB 1\n" + glsl_final_pass(height=height),
    }


def _target(size, fmt: str, filt: str, depth: bool = False) -> dict[str, Any]:
    return {"size": [int(s) for s in size], "format": fmt, "filter": filt, "wrap": "clamp", "depth": depth}


def _graph(scene: Any, textures: dict[str, list[np.ndarray]]) -> dict[str, Any]:
    W, H = scene.width, scene.height
    f = edge_downsample(H)
    low = (-(-W // f), -(-H // f))
    inputs = {
        "mix_lut": {"kind": "3d", "format": "RGB32F", "filter": "linear", "wrap": "clamp",
                    "layout": "(mix, unlit, wash, rgb): x = wash, y = unlit, z = mix; linear RGB"},
        "screen0": {"kind": "2d", "format": "RGBA32F", "filter": "nearest", "wrap": "repeat",
                    "layout": "paper height, paper shade, turbulence (wash), dispersion (wash); row 0 = the image's top row"},
        "screen1": {"kind": "2d", "format": "RG32F", "filter": "nearest", "wrap": "repeat",
                    "layout": "turbulence (unlit), dispersion (unlit)"},
    }  # fmt: skip
    if "tam" in textures:
        inputs["tam"] = {"kind": "2d", "format": "RG32F", "filter": "linear_mipmap_linear", "wrap": "repeat",
                         "layout": "the tonal art map's atlas (diffwash.look.tam_atlas): 8 tiles in rows, tile k the ink of tones "
                                   "k and k + 1 (R, G; tone 0 blank), each padded by rows wrapped from its other end; level k is "
                                   "the map's own mip level k"}  # fmt: skip
    for name, spec in inputs.items():
        spec["files"] = [f"{name}.npy"] if len(textures[name]) == 1 else [f"{name}_level{k}.npy" for k in range(len(textures[name]))]
        spec["shape"] = list(textures[name][0].shape)
    geometry_inputs = {"look_shadow_map": "shadow_map", **({"look_tam": "tam"} if "tam" in textures else {})}
    fullscreen = {"vertex": "fullscreen.vert", "draw": "fullscreen", "depth_test": False, "cull": False, "clear": None}
    mesh = {"draw": "mesh", "depth_test": True}
    return {
        "size": [W, H],
        "render_targets": {
            "shadow_map": _target((SHADOW_MAP_SIZE, SHADOW_MAP_SIZE), "R32F", "nearest", depth=True),
            "gbuffer": _target((W, H), "RGBA32F", "nearest", depth=True),
            "edge_a": _target(low, "RGBA32F", "linear"),
            "edge_b": _target(low, "RGBA32F", "linear"),
        },
        "textures": inputs,
        "attributes": {name: {"location": loc, "glb": glb} for name, (loc, glb) in LOOK_ATTRIBUTES.items()},
        "passes": [
            {"name": "shadow_depth", "vertex": "depth.vert", "fragment": "depth.frag", "target": "shadow_map", **mesh,
             "cull": False, "clear": {"colour": [1.0, 1.0, 1.0, 1.0], "depth": 1.0}, "inputs": {}, "when": "light"},
            {"name": "geometry", "vertex": "geometry.vert", "fragment": "geometry.frag", "target": "gbuffer", **mesh,
             "cull": bool(scene.cull_backfaces), "clear": {"colour": [0.0, 0.0, 0.0, 0.0], "depth": 1.0}, "inputs": geometry_inputs},
            {"name": "edge_downsample", "fragment": "edge_downsample.frag", "target": "edge_a", **fullscreen, "inputs": {"look_source": "gbuffer"}},
            {"name": "edge_rows", "fragment": "edge_rows.frag", "target": "edge_b", **fullscreen, "inputs": {"look_source": "edge_a"}},
            {"name": "edge_columns", "fragment": "edge_columns.frag", "target": "edge_a", **fullscreen, "inputs": {"look_source": "edge_b"}},
            {"name": "final", "fragment": "final.frag", "target": "screen", **fullscreen,
             "inputs": {"look_gbuffer": "gbuffer", "look_edge_blurred": "edge_a", "look_screen0": "screen0",
                        "look_screen1": "screen1", "look_mix_lut": "mix_lut"}},
        ],
    }  # fmt: skip


def look_export(scene: Any, params: Any = None, *, target: str = "webgl2") -> LookExport:
    """The look's passes, textures and uniforms for a scene whose `watercolour` is set.

    **Arguments:**

    - `scene`: the `Scene`; its image size is the passes' (the edge blur and
      the screen tile are in pixels).
    - `params`: shading `Params` (default: the scene's).
    - `target`: `"webgl2"` or `"glsl330"`.
    """
    wc = scene.watercolour
    if wc is None:
        raise ValueError("the scene has no watercolour look")
    p = scene.params if params is None else params
    textures, wash_max, unlit_max = look_textures(scene, p)
    mesh_vertices = len(np.asarray(scene.mesh.vertices))
    zeros = np.zeros(mesh_vertices, np.float32)
    attributes = {
        "_MIX": zeros if wc.mix is None else np.asarray(wc.mix, np.float32),
        "_STROKE": zeros if wc.strokes is None else np.asarray(wc.strokes, np.float32),
    }
    return LookExport(
        target=target,
        shaders=_shaders(target, scene.height, wc.tam is not None),
        graph=_graph(scene, textures),
        textures=textures,
        uniforms=look_frame_uniforms(scene, p, wash_max, unlit_max),
        attributes=attributes,
    )


def retarget(look: LookExport, target: str) -> LookExport:
    """The same passes with their shaders for another target (the textures and uniforms do not change)."""
    height = look.graph["size"][1]
    return dataclasses.replace(look, target=target, shaders=_shaders(target, height, "tam" in look.textures))


def write_look(folder: Path, look: LookExport) -> list[Path]:
    """Write the look's shaders, textures (`.npy`), `passes.json`, `uniforms.json` and `README.md` into `folder`."""
    folder.mkdir()
    written = []
    for name, text in look.shaders.items():
        (folder / name).write_text(text, encoding="utf-8")
        written.append(folder / name)
    for name, spec in look.graph["textures"].items():
        for file, level in zip(spec["files"], look.textures[name]):
            np.save(folder / file, level)
            written.append(folder / file)
    graph = {"//": "the watercolour look's passes in drawing order; README.md explains them", "target": look.target, **look.graph}
    uniforms = {"//": "values of the look's uniforms for this scene; matrices are row-major (m[row][col])", **look.uniforms}
    for name, data in (("passes.json", graph), ("uniforms.json", uniforms)):
        (folder / name).write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        written.append(folder / name)
    (folder / "README.md").write_text(_readme(look), encoding="utf-8")
    return [*written, folder / "README.md"]


def _readme(look: LookExport) -> str:
    """`README.md`: the passes, their inputs and outputs, for a technical artist wiring the look into an engine."""
    g = look.graph
    W, H = g["size"]
    targets = "\n".join(
        f"| `{n}` | {t['size'][0]}x{t['size'][1]} | {t['format']} | {t['filter']} | {'yes' if t['depth'] else 'no'} |" for n, t in g["render_targets"].items()
    )
    textures = "\n".join(
        f"| `{n}` | {', '.join(f'`{f}`' for f in t['files'])} | {t['kind']} {t['format']} | {t['filter']}, {t['wrap']} | {t['layout']} |"
        for n, t in g["textures"].items()
    )
    passes = "\n".join(
        f"| {i + 1}. `{p['name']}` | `{p.get('vertex', 'fullscreen.vert')}` + `{p['fragment']}` | {p['draw']} | "
        f"{', '.join(f'`{u}` <- `{t}`' for u, t in p['inputs'].items()) or '-'} | `{p['target']}` |"
        for i, p in enumerate(g["passes"])
    )
    attributes = ", ".join(f"`{n}` at location {a['location']} (GLB `{a['glb']}`)" for n, a in g["attributes"].items())
    return _README.format(target=look.target, W=W, H=H, targets=targets, textures=textures, passes=passes, attributes=attributes)


_README = """\
# The watercolour look's passes ({target})

Written by `diffwash export` for a scene with a `"watercolour"` object: the
passes that draw the look in real time, as `diffwash preview` (OpenGL) and
`viewer.html` (WebGL2) run them. Every shader is generated by `diffwash.look`
from the same constants as the differentiable renderer (`diffwash render`);
docs/watercolour.md explains each effect and docs/realtime.md the export.
The look is defined at this image size, {W}x{H}: the edge blur's width, its
reduced grid and the paper tile are in pixels (export again for another size).

## Files

- `passes.json`: everything below, machine-readable: the render targets, the
  input textures (file, format, filtering, layout), the vertex attributes and
  the passes in drawing order, each with its shaders, the textures it reads
  (sampler uniform <- texture or render target), its target, clears and state.
- `uniforms.json`: the value of every uniform the passes declare (a pass sets
  those its program uses). Matrices are row-major (`m[row][col]`): transpose
  them (or pass `transpose`) when uploading column-major. `look_edge_weights`
  is a `float[]` array; `look_flip_rows`, `look_rows` are `int`, `two_sided` a `bool`.
- `*.vert`, `*.frag`: the shaders (`#version` line included). `final.frag`
  starts with `#define LOOK_OUTPUT_SRGB 1`: it writes display sRGB into an
  8-bit target; set it to 0 to write linear RGB into an sRGB or HDR target.
- `*.npy`: the input textures, float32, little-endian, row-major (NumPy's
  format: a short header, then the values; row 0 is uploaded first).
- The mesh is `../mesh.glb`: {attributes}. `_MIX` is the pigment
  mix per vertex, `_STROKE` the brush-stroke layer (both 0 when the effect is off).

## Render targets

| name | size | format | filtering | depth buffer |
|---|---|---|---|---|
{targets}

Float colour targets need `EXT_color_buffer_float` in WebGL2; where 32-bit float textures cannot be
filtered (no `OES_texture_float_linear`), make the linearly filtered edge targets RGBA16F. All
targets clamp to edge.

## Input textures

| name | files | format | filtering, wrap | layout |
|---|---|---|---|---|
{textures}

The tonal art map's levels are its own (strokes nested across levels), not
filtered ones: upload each file as that mip level.

## Passes, in drawing order

| pass | shaders | draws | reads | writes |
|---|---|---|---|---|
{passes}

- `shadow_depth` runs once, and again whenever the light moves: the light's
  orthographic view (`look_light_view_projection`, fitted to the mesh's
  bounding sphere by `diffwash.look.light_view_projection`) into `shadow_map`
  (cleared to 1, depth test `LESS`, no culling).
- `geometry` draws the mesh (depth test `LESS`, back-face culling as
  `passes.json` says) into the float G-buffer, cleared to 0: per pixel the
  wash and unlit thickness (with self-shadowing and hatching), the mix and
  the stroke value.
- The three edge passes and `final` draw one full-screen triangle (3
  vertices, no vertex buffer: `fullscreen.vert` builds it from
  `gl_VertexID`) with the viewport set to their target's size.
- `final` writes the picture; the paper colour shows where the G-buffer is
  empty (thickness 0). `look_flip_rows = 1` says the G-buffer's row 0 is the
  image's bottom row, as OpenGL renders it.

When the camera moves, update `view_projection`, `eye` and `eye_forward` (the
unit vector from the eye to the target); when the light moves,
`light_direction` and `look_light_view_projection`, then run `shadow_depth` again.
"""
