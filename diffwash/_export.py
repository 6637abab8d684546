"""Export a scene for real-time use: LUT + sidecar, shaders, mesh (GLB), and a WebGL2 viewer.

`export(scene, folder)` writes

- `lut.png` + `lut.json` (or `lut_R.png`, `lut_T.png` for an R/T LUT; `.exr` /
  `.npy` on request): the baked table and its sidecar (`diffwash.lut`);
- `watercolour_per_vertex.vert/.frag`, `watercolour_per_pixel.vert/.frag`: the
  shaders for the chosen target (`diffwash._glsl`);
- `watercolour.glsl`: the model's functions and uniforms without a `main`, to
  include in an engine's own shaders;
- `uniforms.json`: the scene's values of every uniform the shaders declare;
- `mesh.glb`: the mesh with its normals (binary glTF, via trimesh), and the
  material: the LUT as a texture and the uniforms in the material's `extras`
  (`diffwash._gltf`);
- `scene.json`: the scene, with explicit pigments, pointing at `mesh.glb`;
- `viewer.html`: a self-contained WebGL2 page (`diffwash._viewer`);
- for a scene with a `"watercolour"` object, `look/`: the look's passes
  (shaders, input textures as `.npy`, `passes.json`, `uniforms.json`, a
  `README.md`; `diffwash._look_export`), the mesh's per-vertex mix and stroke
  layer as the GLB's `_MIX` and `_STROKE` attributes, and the viewer draws the look;
- for the `threejs` target, `diffwash-material.js` (an ES module building a
  `THREE.ShaderMaterial`), `index.html` (draws `mesh.glb` with it) and
  `three/` (three.js's module files; `diffwash._threejs`);
- for the `blender` target, `blender_scene.py` (builds the scene in Blender: node
  groups generated from the model, camera, render settings), `blender_data.npz`
  (mesh and LUT) and, where `bpy` is importable, `scene.blend`
  (`diffwash._blender`); its shader files are GLSL 3.30. It draws the model
  with the colour LUT (`kind="rt"` is refused), and a watercolour look's per-pixel
  effects (paper, unevenness, strokes, mix); edge darkening, the own shadow and
  hatching it cannot carry: a scene that turns them on is refused unless `partial`.

The folder appears whole or not at all: everything is written into a temporary
folder beside it, which is then renamed.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from . import lut as _lut
from ._errors import DiffwashError
from ._gltf import png16, with_material
from ._glsl import SHADING_MODES, functions_source, shader_file_names, shader_sources, uniform_values
from ._io import atomic_folder
from ._lazy import lazy
from ._look_export import LOOK_FOLDER, LookExport, look_export, retarget, write_look
from ._scene import Mesh, Scene, load_scene, scene_to_dict
from ._blender import leaves_out, write_blender
from ._choices import EXPORT_TARGETS
from ._threejs import write_threejs
from ._version import __version__
from ._viewer import viewer_html
from .shading import Params

trimesh = lazy("trimesh")

__all__ = ["export", "mesh_glb", "material_glb", "EXPORT_FILES"]

#: What a colour-LUT export with the default format holds.
EXPORT_FILES = (
    "lut.png",
    "lut.json",
    "watercolour_per_vertex.vert",
    "watercolour_per_vertex.frag",
    "watercolour_per_pixel.vert",
    "watercolour_per_pixel.frag",
    "watercolour.glsl",
    "uniforms.json",
    "mesh.glb",
    "scene.json",
    "viewer.html",
)


def mesh_glb(mesh: Mesh, attributes: dict[str, np.ndarray] | None = None) -> bytes:
    """The mesh (vertices, faces, vertex normals) as binary glTF 2.0.

    `attributes`: extra per-vertex float attributes, by glTF name (application
    attributes start with `_`, e.g. the look's `_MIX` and `_STROKE`).
    """
    m = trimesh.Trimesh(
        vertices=np.asarray(mesh.vertices, np.float64),
        faces=np.asarray(mesh.faces, np.int64),
        vertex_normals=np.asarray(mesh.normals, np.float64),
        process=False,
    )
    for name, values in (attributes or {}).items():
        m.vertex_attributes[name] = np.asarray(values, np.float32)
    return m.export(file_type="glb")


#: The uniforms `mesh.glb`'s material carries (the matrices and `eye` come from the engine's camera).
_MATERIAL_UNIFORMS = ("k_wash", "k_specular", "shininess", "k_unlit", "gain", "bias", "wash_reduction",
                      "light_direction", "paper", "lut_wash_max", "lut_unlit_max", "two_sided")  # fmt: skip


def material_glb(glb: bytes, scene: Scene, params: Params, table: _lut.Lut) -> bytes:
    """`glb` (the mesh) with the watercolour material: the LUT as 16-bit sRGB PNG texture(s), the uniforms in `extras`.

    The material's `extras.diffwash` (docs/realtime.md, "glTF"): `uniforms`
    (the scene's values, named as in the GLSL), `lut` (size, kind, encoding,
    range, addressing), `textures` (sampler uniform -> glTF texture index),
    `shading`, `camera`, `shaders` and the versions.
    """
    u = uniform_values(scene, params, lut=table)
    encoded = _lut.encoded(table, "png16")
    names = ["lut"] if table.kind == "colour" else ["lut_reflectance", "lut_transmittance"]
    images = {name: png16(encoded[..., 3 * i : 3 * i + 3]) for i, name in enumerate(names)}
    cam = scene.camera
    extras = {
        "format": "diffwash-material",
        "format_version": 1,
        "diffwash_version": __version__,
        "uniforms": {k: u[k] for k in _MATERIAL_UNIFORMS},
        "lut": {
            "kind": table.kind,
            "size": list(table.size),
            "wash_max": float(table.wash_max),
            "unlit_max": float(table.unlit_max),
            "encoding": "srgb",
            "storage": "png16",
            "addressing": "uv = (clamp(thickness / max, 0, 1) * (size - 1) + 0.5) / size; row 0 (v = 0) is the image's top row, no unlit pigment",
        },
        "shading": scene.shading,
        "camera": {k: np.asarray(getattr(cam, k), np.float64).tolist() for k in ("eye", "target", "up", "fov_y", "near", "far")},
        "image_size": [scene.width, scene.height],
        "shaders": "watercolour_per_pixel.vert/.frag, watercolour_per_vertex.vert/.frag, watercolour.glsl (LUT_SRGB 1 for these textures)",
    }  # fmt: skip
    return with_material(glb, images, extras, base_colour=u["paper"], double_sided=u["two_sided"])


def _scene_of(scene_or_path: Scene | str | os.PathLike) -> Scene:
    if isinstance(scene_or_path, Scene):
        return scene_or_path
    if isinstance(scene_or_path, (str, os.PathLike)):
        return load_scene(scene_or_path)
    raise TypeError(f"export() takes a Scene or a scene file path, got {type(scene_or_path).__name__}")


def _is_export(folder: Path) -> bool:
    return (folder / "viewer.html").is_file() and any(folder.glob("*.json"))


def _check_blender(scene: Scene, kind: str, partial: bool) -> None:
    """Refuse what the Blender target cannot draw: the R/T LUT, and, unless `partial`, a watercolour look with an
    effect beyond shader nodes (`diffwash._blender.leaves_out`; the rest of the look is carried)."""
    left = leaves_out(scene)
    if left and not partial:
        raise DiffwashError(f"Blender's shader nodes cannot draw the look's {', '.join(left)} (docs/blender.md): turn "
                            "them off in the scene, or export the rest of the look with --partial (Python: "
                            "partial=True)", file=scene.path, field="watercolour")  # fmt: skip
    if kind != "colour":
        raise DiffwashError("the Blender target reads the colour LUT; R and T over a paper uniform (--rt) are for "
                            "the GLSL targets", field="rt")  # fmt: skip


def export(
    scene: Scene | str | os.PathLike,
    folder: str | os.PathLike,
    *,
    params: Params | None = None,
    target: str = "webgl2",
    size: int | tuple[int, int] = 256,
    fmt: str = "png16",
    kind: str = "colour",
    overwrite: bool = False,
    partial: bool = False,
) -> list[Path]:
    """Write the LUT, its sidecar, the shaders, the mesh and the viewer into `folder`.

    **Arguments:**

    - `scene`: a `Scene` or the path of a scene file.
    - `folder`: the output folder. It must not exist, or be empty, or (with
      `overwrite`) hold a previous export, which is replaced.
    - `params`: shading `Params` (default: the scene's).
    - `target`: `"webgl2"` (GLSL ES 3.00) or `"glsl330"` (OpenGL 3.3 core) for
      the shader files (the viewer always uses WebGL2 shaders from the same
      template); `"threejs"` also writes the three.js module, page and
      library (`diffwash._threejs`), which draw the look too; `"blender"` writes
      GLSL 3.30 files and a Blender scene (`diffwash._blender`, docs/blender.md).
    - `size`: LUT samples per axis (2..4096), or `(N, M)`.
    - `fmt`: LUT file format: `"png16"`, `"png8"`, `"exr"` or `"npy"`.
    - `kind`: `"colour"` or `"rt"` (R and T, composited over a `paper` uniform).
    - `overwrite`: replace an existing export in `folder`.
    - `partial`: the Blender target, a scene whose look turns on effects shader nodes cannot draw (edge darkening,
      the own shadow, hatching): export the rest of the look instead of refusing the scene.

    A scene with a watercolour look also gets `look/` (its passes for
    `target`, `diffwash._look_export`), and the viewer draws the look.

    **Returns:**

    The paths written, in `folder`.
    """
    if target not in EXPORT_TARGETS:
        raise DiffwashError(f"must be one of {', '.join(EXPORT_TARGETS)}, got {target!r}", field="target")
    if fmt not in _lut.FORMATS:
        raise DiffwashError(f"must be one of {', '.join(_lut.FORMATS)}, got {fmt!r}", field="format")
    _lut.check_size(size)
    scene = _scene_of(scene)
    params = scene.params if params is None else params
    if target == "blender":
        _check_blender(scene, kind, partial)
    folder = Path(folder)
    if folder.exists():
        if not folder.is_dir():
            raise DiffwashError("exists and is not a folder", file=folder)
        if any(folder.iterdir()) and not (overwrite and _is_export(folder)):
            why = "holds files that are not a diffwash export" if overwrite else "is not empty (use --overwrite to replace a previous export)"
            raise DiffwashError(why, file=folder)
    if not (folder.parent if str(folder.parent) else Path(".")).is_dir():
        raise DiffwashError("output folder's parent does not exist", file=folder.parent)

    table = _lut.bake(params, size, kind=kind)
    # The look's passes for three.js are its WebGL2 shaders (RawShaderMaterials: look/ holds those);
    # the Blender target's shader files are GLSL 3.30 (its node groups are in blender_scene.py).
    shader_target = "glsl330" if target == "blender" else target
    look_target = "webgl2" if target == "threejs" else shader_target
    look = None if scene.watercolour is None else look_export(scene, params, target=look_target)
    with atomic_folder(folder) as tmp:
        written = _write_plain(tmp, scene, params, table, target=shader_target, fmt=fmt, kind=kind)
        viewer_look = look if look is None or look_target == "webgl2" else retarget(look, "webgl2")
        written += _write_scene(tmp, folder, scene, params, table, look, viewer_look)
        if target == "threejs":
            written += write_threejs(tmp, scene, table, params=params, look=viewer_look)
        if target == "blender":
            written += write_blender(tmp, scene, table, params=params)
    return [folder / p.relative_to(tmp) for p in written]


def _write_plain(tmp: Path, scene: Scene, params: Params, table: _lut.Lut, *, target: str, fmt: str, kind: str) -> list[Path]:
    """The plain model's LUT, shaders, shader functions and uniforms."""
    written = _lut.save(tmp / f"lut{_lut.FORMATS[fmt][0]}", table, fmt)
    colour = "lut-rt" if kind == "rt" else "lut"
    lut_srgb = _lut.FORMATS[fmt][1] == "srgb"
    for mode in SHADING_MODES:
        vert, frag = shader_sources(target, mode, colour=colour, lut_srgb=lut_srgb, output_srgb=True)
        for name, text in zip(shader_file_names(mode), (vert, frag)):
            (tmp / name).write_text(text, encoding="utf-8")
            written.append(tmp / name)
    (tmp / "watercolour.glsl").write_text(
        functions_source(target, colour=colour, lut_srgb=lut_srgb, output_srgb=True), encoding="utf-8"
    )
    written.append(tmp / "watercolour.glsl")
    uniforms = uniform_values(scene, params, lut=table)
    uniforms = {"//": "values of the shaders' uniforms for this scene; matrices are row-major (m[row][col])", **uniforms}
    (tmp / "uniforms.json").write_text(json.dumps(uniforms, indent=2) + "\n", encoding="utf-8")
    return [*written, tmp / "uniforms.json"]


def _write_scene(
    tmp: Path, folder: Path, scene: Scene, params: Params, table: _lut.Lut, look: LookExport | None, viewer_look: LookExport | None
) -> list[Path]:
    """The mesh, the scene file, the look's passes (when the scene has one) and the viewer."""
    glb = mesh_glb(scene.mesh, None if look is None else look.attributes)
    (tmp / "mesh.glb").write_bytes(material_glb(glb, scene, params, table))
    data = scene_to_dict(scene, params, relative_to=folder)
    data["mesh"] = "mesh.glb"
    (tmp / "scene.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    written = [tmp / "mesh.glb", tmp / "scene.json"]
    if look is not None:
        written += write_look(tmp / LOOK_FOLDER, look)
    (tmp / "viewer.html").write_text(viewer_html(scene, table, glb, params=params, look=viewer_look), encoding="utf-8")
    return [*written, tmp / "viewer.html"]
