"""`viewer.html`: a self-contained WebGL2 page showing a scene with the exported shaders and LUT.

The page embeds everything (no network): the `webgl2` shaders of both shading
modes (the same text `diffwash export` writes for that target), the LUT as the
exported PNG's sRGB-encoded values in half floats, and the mesh as the exported
GLB (base64). Its first frame is the scene's camera and light, so it can be
compared with `diffwash render`; then the mouse orbits the camera and moves the
light, and a panel toggles per-vertex / per-pixel thickness and tunes the
constants that do not change the LUT's range.

For a scene with a `"watercolour"` object the page also embeds the look's
passes (`diffwash._look_export`: the `webgl2` shaders, the pass graph, the
uniforms, the input textures as half floats, the mix and stroke layer in the
GLB) and draws them: a light depth pass, a float G-buffer, the edge blur and
the final pass. That needs `EXT_color_buffer_float`; without it the page
says so and shows the plain model.
"""

from __future__ import annotations

import base64
import html
import json
from importlib import resources
from typing import Any

import numpy as np

from ._glsl import shader_file_names, shader_sources, uniform_values
from ._look_export import LookExport
from ._version import __version__
from .colorimetry import to_display
from .lut import Lut

__all__ = ["viewer_html", "look_config", "look_runner_source"]

_FLOATS = ["k_wash", "k_specular", "shininess", "k_unlit", "gain", "bias", "wash_reduction", "lut_wash_max", "lut_unlit_max"]
_VEC3S = ["light_direction", "eye", "paper"]


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def _live_constants(u: dict) -> list[dict]:
    """Sliders for the constants that keep the thicknesses within the LUT's range."""
    shininess = u["shininess"]
    return [
        {"name": "shininess", "min": 0, "max": max(200.0, 2 * shininess), "step": 0.5},
        {"name": "gain", "min": 0.01, "max": 0.99, "step": 0.01},
        {"name": "bias", "min": 0.01, "max": 0.99, "step": 0.01},
        {"name": "wash_reduction", "min": 0, "max": 1, "step": 0.01},
    ]


def _light_frustum(look: LookExport, light: np.ndarray, centre: np.ndarray) -> dict[str, Any]:
    """What the page needs to redo `light_view_projection` when the light moves, read off the scene's matrix.

    Only the light's basis turns with it: rows 0 and 1 are `(x, -x.c) / r`,
    `(y, -y.c) / r` and row 2 is `(a d, -a d.c + k)` (`d` the unit direction
    towards the light, `c` the bounding box's centre), with the half-size `r`,
    the depth scale `a` and offset `k` the same for every direction (the
    page's `lightViewProjection`; a test holds it against this matrix).
    """
    vp = np.asarray(look.uniforms["look_light_view_projection"], np.float64)
    d = light / np.linalg.norm(light)
    a = float(vp[2, :3] @ d)
    return {
        "centre": centre.tolist(),
        "half_size": float(1 / np.linalg.norm(vp[0, :3])),
        "depth_scale": a,
        "depth_offset": float(vp[2, 3] + a * (d @ centre)),
    }


def look_config(look: LookExport, vertices: np.ndarray) -> dict[str, Any]:
    """The look as a page embeds it (the viewer, the three.js module): shaders, graph, uniforms, half-float textures, light."""
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    textures = {
        name: {
            "channels": int(levels[0].shape[-1]),
            "levels": [{"shape": list(lv.shape[:-1]), "half_float": _b64(np.ascontiguousarray(lv).astype("<f2").tobytes())} for lv in levels],
        }
        for name, levels in look.textures.items()
    }
    light = _light_frustum(look, np.asarray(look.uniforms["light_direction"], np.float64), centre)
    return {"graph": look.graph, "shaders": look.shaders, "uniforms": look.uniforms, "textures": textures, "light": light}


def viewer_html(
    scene: Any, lut: Lut, mesh_glb: bytes, *, params: Any = None, title: str | None = None, look: LookExport | None = None
) -> str:
    """The viewer page for `scene` drawn with `lut` and the mesh `mesh_glb` (GLB bytes).

    `look`: the scene's watercolour look for the `webgl2` target
    (`diffwash._look_export.look_export`); the mesh must then carry its
    `_MIX` and `_STROKE` attributes.

    **Returns:**

    The HTML text.
    """
    p = scene.params if params is None else params
    colour = "lut-rt" if lut.kind == "rt" else "lut"
    shaders = {}
    for mode in ("per-vertex", "per-pixel"):
        vert, frag = shader_sources("webgl2", mode, colour=colour, lut_srgb=True, output_srgb=True)
        vname, fname = shader_file_names(mode)
        shaders[mode] = {"vert": vert, "frag": frag, "vert_name": vname, "frag_name": fname}
    encoded = to_display(np.asarray(lut.values, np.float64))
    names = ["lut"] if lut.kind == "colour" else ["lut_reflectance", "lut_transmittance"]
    textures = [
        {"uniform": name, "half_float": _b64(np.ascontiguousarray(encoded[..., 3 * i : 3 * i + 3]).astype("<f2").tobytes())}
        for i, name in enumerate(names)
    ]
    u = uniform_values(scene, p, lut=lut)
    vertices = np.asarray(scene.mesh.vertices, np.float64)
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    cam = scene.camera
    config = {
        "width": scene.width,
        "height": scene.height,
        "shading": scene.shading,
        "shaders": shaders,
        "lut": {"size": list(lut.size), "kind": lut.kind, "textures": textures},
        "mesh_glb": _b64(mesh_glb),
        "mesh_faces": int(np.asarray(scene.mesh.faces).shape[0]),
        "centre": centre.tolist(),
        "radius": float(np.max(np.linalg.norm(vertices - centre, axis=1))),
        "camera": {k: np.asarray(getattr(cam, k), np.float64).tolist() for k in ("eye", "target", "up", "fov_y", "near", "far")},
        "uniforms": {k: u[k] for k in [*_FLOATS, *_VEC3S, "two_sided"]},
        "float_uniforms": _FLOATS,
        "vec3_uniforms": _VEC3S,
        "live_constants": _live_constants(u),
        "background": to_display(np.asarray(u["paper"], np.float64)).tolist(),  # the paper as linear sRGB
        "pigments": {"wash": p.wash.name, "unlit": p.unlit.name},
        "version": __version__,
        "look": None if look is None else look_config(look, vertices),
    }
    # JSON is valid JavaScript; "</" is escaped so the data cannot close the <script> element.
    blob = json.dumps(config, separators=(",", ":")).replace("</", "<\\/")
    template = (resources.files("diffwash") / "data" / "viewer.html").read_text(encoding="utf-8")

    name = title if title is not None else (scene.path or "scene")
    return template.replace("__LOOK_RUNNER__", look_runner_source()).replace("__TITLE__", html.escape(str(name))).replace("__CONFIG__", blob)


def look_runner_source() -> str:
    """`diffwash/data/look-runner.js`: the JavaScript that runs the look's passes (the viewer page and the widget)."""
    return (resources.files("diffwash") / "data" / "look-runner.js").read_text(encoding="utf-8")
