"""The three.js target: an ES module that builds the material, a page that draws the scene, three.js itself.

`diffwash export SCENE --target threejs` writes, beside the plain model's files,

- `diffwash-material.js`: an ES module (`import * as THREE from "three"`) that
  exports `createWatercolourMaterial({shading})`, a `THREE.ShaderMaterial`
  (`glslVersion: THREE.GLSL3`) whose shaders are `diffwash._glsl`'s for the
  `threejs` target, whose uniforms are named as in that GLSL, and whose LUT
  is a `THREE.DataTexture` of the baked linear values in half floats (linear
  filtering, clamp to edge, no mipmaps, no flip: the texel-centre addressing
  of docs/realtime.md is in the shader); `createCamera()`, the scene's
  camera; `paperColour()`, the paper as a `THREE.Color`; and `config`.
- `index.html`: loads `mesh.glb` with three's `GLTFLoader`, draws it with the
  material and the scene's camera at the scene's size, and sets
  `document.body.dataset.ready = "1"` once the first frame is drawn; then
  `OrbitControls` orbit the camera.
- `three/`: three.js's module files (MIT), vendored from the npm registry in
  `diffwash/data/threejs/` (its README says which version and files), which
  the page maps with an import map: served as static files, the folder needs
  no network.

Colour: the LUT holds linear values (`LUT_SRGB 0`, the texture's colour space
`THREE.LinearSRGBColorSpace`), and the shader writes the linear colour through
three.js's `linearToOutputTexel` (`OUTPUT_SRGB 0`): display sRGB on the canvas
(`renderer.outputColorSpace`, sRGB by default), linear into a render target,
as three.js's own materials do. The clear colour is the paper, given linear.
"""

from __future__ import annotations

import base64
import html
import json
import shutil
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ._glsl import SHADING_MODES, shader_sources, uniform_values
from ._look_export import LookExport
from ._version import __version__
from .lut import Lut
from ._viewer import look_config
from .shading import CONSTANTS

__all__ = ["THREE_VERSION", "THREEJS_FILES", "THREEJS_FOLDER", "threejs_module", "threejs_page", "write_threejs"]

#: The three.js release vendored in `diffwash/data/threejs/` (npm `three`).
THREE_VERSION = "0.180.0"
#: What the three.js target adds to an export.
THREEJS_FILES = ("diffwash-material.js", "index.html", "three")
#: The export's folder holding three.js's module files.
THREEJS_FOLDER = "three"

#: The uniforms the material sets from the scene (the matrices are three.js's own).
_UNIFORMS = [*CONSTANTS, "light_direction", "eye", "paper", "lut_wash_max", "lut_unlit_max", "two_sided"]


def _half_floats(values: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(values).astype("<f2").tobytes()).decode("ascii")


def _config(scene: Any, lut: Lut, params: Any, title: str, look: LookExport | None) -> dict[str, Any]:
    """What the module embeds: the shaders of both modes, the uniforms, the LUT, the camera and size, the look."""
    colour = "lut-rt" if lut.kind == "rt" else "lut"
    shaders = {}
    for mode in SHADING_MODES:
        vert, frag = shader_sources("threejs", mode, colour=colour, lut_srgb=False, output_srgb=False)
        shaders[mode] = {"vert": vert, "frag": frag}
    values = np.asarray(lut.values, np.float32)
    names = ["lut"] if lut.kind == "colour" else ["lut_reflectance", "lut_transmittance"]
    u = uniform_values(scene, params, lut=lut)
    cam = scene.camera
    return {
        "title": title,
        "diffwash_version": __version__,
        "three_version": THREE_VERSION,
        "width": scene.width,
        "height": scene.height,
        "shading": scene.shading,
        "shaders": shaders,
        "uniforms": {k: u[k] for k in _UNIFORMS},
        "lut": {
            "size": list(lut.size),
            "kind": lut.kind,
            "encoding": "linear",
            "textures": [{"uniform": n, "half_float": _half_floats(values[..., 3 * i : 3 * i + 3])} for i, n in enumerate(names)],
        },
        "camera": {k: np.asarray(getattr(cam, k), np.float64).tolist() for k in ("eye", "target", "up", "fov_y", "near", "far")},
        "look": None if look is None else look_config(look, np.asarray(scene.mesh.vertices, np.float64)),
    }


def _template(name: str) -> str:
    return (resources.files("diffwash") / "data" / name).read_text(encoding="utf-8")


def threejs_module(scene: Any, lut: Lut, *, params: Any = None, title: str | None = None, look: LookExport | None = None) -> str:
    """`diffwash-material.js` for `scene` drawn with `lut`: the ES module's text.

    `look`: the scene's watercolour look for the `webgl2` target
    (`diffwash._look_export.look_export`), which the module then also draws.
    """
    p = scene.params if params is None else params
    name = title if title is not None else str(scene.path or "scene")
    blob = json.dumps(_config(scene, lut, p, name, look), separators=(",", ":"))
    return _template("threejs-material.js").replace("__VERSION__", __version__).replace("__CONFIG__", blob)


def threejs_page(scene: Any, *, title: str | None = None) -> str:
    """`index.html`: the page that draws `mesh.glb` with the module's material and camera."""
    name = title if title is not None else str(scene.path or "scene")
    return _template("threejs-index.html").replace("__TITLE__", html.escape(name)).replace("__THREE_VERSION__", THREE_VERSION)


def write_threejs(folder: Path, scene: Any, lut: Lut, *, params: Any = None, look: LookExport | None = None) -> list[Path]:
    """Write the module, the page and three.js's files into `folder` (beside `mesh.glb`)."""
    (folder / "diffwash-material.js").write_text(threejs_module(scene, lut, params=params, look=look), encoding="utf-8")
    (folder / "index.html").write_text(threejs_page(scene), encoding="utf-8")
    with resources.as_file(resources.files("diffwash") / "data" / "threejs") as source:
        shutil.copytree(source, folder / THREEJS_FOLDER)
    three = sorted(p for p in (folder / THREEJS_FOLDER).rglob("*") if p.is_file())
    return [folder / "diffwash-material.js", folder / "index.html", *three]
