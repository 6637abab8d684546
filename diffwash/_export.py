"""Export a scene for real-time use: LUT + sidecar, shaders, mesh (GLB), and a WebGL2 viewer.

`export(scene, folder)` writes

- `lut.png` + `lut.json` (or `lut_R.png`, `lut_T.png` for an R/T LUT; `.exr` /
  `.npy` on request): the baked table and its sidecar (`diffwash.lut`);
- `watercolour_per_vertex.vert/.frag`, `watercolour_per_pixel.vert/.frag`: the
  shaders for the chosen target (`diffwash._glsl`);
- `watercolour.glsl`: the model's functions and uniforms without a `main`, to
  include in an engine's own shaders;
- `uniforms.json`: the scene's values of every uniform the shaders declare;
- `mesh.glb`: the mesh with its normals (binary glTF, via trimesh);
- `scene.json`: the scene, with explicit pigments, pointing at `mesh.glb`;
- `viewer.html`: a self-contained WebGL2 page (`diffwash._viewer`).

The folder appears whole or not at all: everything is written into a temporary
folder beside it, which is then renamed.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import trimesh

from . import lut as _lut
from ._errors import DiffwashError
from ._io import atomic_folder
from ._glsl import SHADING_MODES, TARGETS, functions_source, shader_file_names, shader_sources, uniform_values
from ._scene import Mesh, Scene, load_scene, scene_to_dict
from ._viewer import viewer_html
from .shading import Params

__all__ = ["export", "mesh_glb", "EXPORT_FILES"]

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


def mesh_glb(mesh: Mesh) -> bytes:
    """The mesh (vertices, faces, vertex normals) as binary glTF 2.0."""
    m = trimesh.Trimesh(
        vertices=np.asarray(mesh.vertices, np.float64),
        faces=np.asarray(mesh.faces, np.int64),
        vertex_normals=np.asarray(mesh.normals, np.float64),
        process=False,
    )
    return m.export(file_type="glb")


def _scene_of(scene_or_path: Scene | str | os.PathLike) -> Scene:
    if isinstance(scene_or_path, Scene):
        return scene_or_path
    if isinstance(scene_or_path, (str, os.PathLike)):
        return load_scene(scene_or_path)
    raise TypeError(f"export() takes a Scene or a scene file path, got {type(scene_or_path).__name__}")


def _is_export(folder: Path) -> bool:
    return (folder / "viewer.html").is_file() and any(folder.glob("*.json"))


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
) -> list[Path]:
    """Write the LUT, its sidecar, the shaders, the mesh and the viewer into `folder`.

    **Arguments:**

    - `scene`: a `Scene` or the path of a scene file.
    - `folder`: the output folder. It must not exist, or be empty, or (with
      `overwrite`) hold a previous export, which is replaced.
    - `params`: shading `Params` (default: the scene's).
    - `target`: `"webgl2"` (GLSL ES 3.00) or `"glsl330"` (OpenGL 3.3 core) for
      the shader files (the viewer always uses WebGL2 shaders from the same
      template).
    - `size`: LUT samples per axis (2..4096), or `(N, M)`.
    - `fmt`: LUT file format: `"png16"`, `"png8"`, `"exr"` or `"npy"`.
    - `kind`: `"colour"` or `"rt"` (R and T, composited over a `paper` uniform).
    - `overwrite`: replace an existing export in `folder`.

    **Returns:**

    The paths written, in `folder`.
    """
    if target not in TARGETS:
        raise DiffwashError(f"must be one of {', '.join(TARGETS)}, got {target!r}", field="target")
    if fmt not in _lut.FORMATS:
        raise DiffwashError(f"must be one of {', '.join(_lut.FORMATS)}, got {fmt!r}", field="format")
    _lut.check_size(size)
    scene = _scene_of(scene)
    params = scene.params if params is None else params
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
    with atomic_folder(folder) as tmp:
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
        glb = mesh_glb(scene.mesh)
        (tmp / "mesh.glb").write_bytes(glb)
        data = scene_to_dict(scene, params, relative_to=folder)
        data["mesh"] = "mesh.glb"
        (tmp / "scene.json").write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
        (tmp / "viewer.html").write_text(viewer_html(scene, table, glb, params=params), encoding="utf-8")
        written += [tmp / n for n in ("uniforms.json", "mesh.glb", "scene.json", "viewer.html")]
    return [folder / p.name for p in written]
