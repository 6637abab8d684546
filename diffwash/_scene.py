"""Scene files: JSON that names a mesh, a camera, a light, two pigments and the constants.

```
{"mesh": "knot.ply",                       // relative to the scene file; any format trimesh loads
 "image": {"width": 512, "height": 512},
 "camera": {"eye": [0,0,3], "target": [0,0,0], "up": [0,1,0], "fov_y": 40},
 "light": {"direction": [1,1,1]},          // towards the light, world space
 "shading": "per-pixel",                   // or "per-vertex"
 "paper": [0.92, 0.90, 0.84],              // linear reflectance of the paper
 "wash": {"pigment": "Quinacridone Rose"}, // or {"K": [...], "S": [...]}, or a pigment file
 "unlit": {"pigment": "French Ultramarine"},
 "k_wash": 1.0, "k_specular": 1.0, "shininess": 20, "k_unlit": 1.0,
 "gain": 0.5, "bias": 0.5, "wash_reduction": 0.0}
```

Required: `mesh`, `camera.eye`, `camera.target`, `light.direction`, `wash`,
`unlit`. Everything else has a default (docs/scene-format.md lists them).
"""

from __future__ import annotations

import difflib
import logging
import math
import os
from pathlib import Path
from typing import Any

import equinox as eqx
import numpy as np
import trimesh
from jaxtyping import Float, Int

from . import pigments as _pigments
from ._camera import Camera
from ._errors import DiffwashError
from ._io import FLOAT32_MAX, check_float32, finite_number, read_json, write_json
from .shading import DEFAULT_CONSTANTS, DEFAULT_PAPER, Params

__all__ = ["Mesh", "Scene", "load_scene", "load_mesh", "parse_scene", "save_scene", "referenced_files", "MAX_IMAGE_SIDE"]

#: Largest image side the renderer accepts (pixels).
MAX_IMAGE_SIDE = 8192
SHADING_MODES = ("per-pixel", "per-vertex")
BACKFACE_MODES = ("auto", "cull", "both")

_TOP_KEYS = {
    "mesh", "image", "camera", "light", "shading", "paper", "wash", "unlit", "backfaces", "meta",
    *DEFAULT_CONSTANTS,
}  # fmt: skip
_CAMERA_KEYS = {"eye", "target", "up", "fov_y", "near", "far"}


class Mesh(eqx.Module):
    """A triangle mesh: `vertices` (V, 3), `faces` (F, 3) int32, unit `normals` (V, 3).

    `closed` is True for a watertight mesh (its back faces are never seen).
    """

    vertices: Float[np.ndarray, "V 3"]
    faces: Int[np.ndarray, "F 3"]
    normals: Float[np.ndarray, "V 3"]
    closed: bool = eqx.field(static=True, default=False)


class Scene(eqx.Module):
    """Everything needed to render one image, as a pytree.

    **Fields:**

    - `mesh`: the `Mesh`.
    - `camera`: the `Camera`.
    - `params`: the shading `Params` (pigments, paper, light, constants).
    - `width`, `height`: image size in pixels.
    - `shading`: `"per-pixel"` or `"per-vertex"`.
    - `backfaces`: `"cull"` (hide triangles facing away), `"both"` (draw them,
      shaded with the normal turned towards the eye) or `"auto"` (cull for closed
      meshes, both for open ones).
    - `path`: the scene file it came from, if any.
    """

    mesh: Mesh
    camera: Camera
    params: Params
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    shading: str = eqx.field(static=True, default="per-pixel")
    backfaces: str = eqx.field(static=True, default="auto")
    path: str | None = eqx.field(static=True, default=None)

    @property
    def cull_backfaces(self) -> bool:
        """Whether back-facing triangles are hidden."""
        return self.backfaces == "cull" or (self.backfaces == "auto" and self.mesh.closed)


def _fail(msg: str, file: Any, field: str | None = None) -> DiffwashError:
    return DiffwashError(msg, file=file, field=field)


def _number(obj: dict, key: str, file: Any, field: str, *, default: Any = None, lo=None, hi=None, lo_open=False):
    if key not in obj:
        if default is None:
            raise _fail("missing key", file, field)
        return float(default)
    v = obj[key]
    if not finite_number(v):
        raise _fail(f"must be a finite number, got {v!r}", file, field)
    v = check_float32(v, file=file, field=field)
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise _fail(f"must be {'>' if lo_open else '>='} {lo}, got {v!r}", file, field)
    if hi is not None and v > hi:
        raise _fail(f"must be <= {hi}, got {v!r}", file, field)
    return float(v)


def _vec3(obj: dict, key: str, file: Any, field: str, default: Any = None, nonneg: bool = False) -> np.ndarray:
    if key not in obj:
        if default is None:
            raise _fail("missing key", file, field)
        return np.asarray(default, np.float64)
    v = obj[key]
    if not isinstance(v, list) or len(v) != 3 or not all(finite_number(c) for c in v):
        raise _fail(f"must be a list of 3 finite numbers, got {v!r}", file, field)
    for i, c in enumerate(v):
        check_float32(c, file=file, field=f"{field}[{i}]")
    if nonneg and any(c < 0 for c in v):
        raise _fail(f"must be >= 0, got {v!r}", file, field)
    return np.asarray(v, np.float64)


def _object(obj: dict, key: str, file: Any, *, required: bool = True) -> dict:
    if key not in obj:
        if required:
            raise _fail("missing key", file, key)
        return {}
    v = obj[key]
    if not isinstance(v, dict):
        raise _fail(f"must be a JSON object, got {type(v).__name__}", file, key)
    return v


def _check_keys(obj: dict, allowed: set[str], file: Any, where: str = "") -> None:
    for k in obj:
        if k not in allowed:
            close = difflib.get_close_matches(k, sorted(allowed), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise _fail(f"unknown key{hint}", file, f"{where}{k}")


def load_mesh(path: str | os.PathLike, *, field: str = "mesh", file: Any = None) -> Mesh:
    """Load a triangle mesh with trimesh (any format it reads), validated.

    Vertex normals are the file's own where it has them, else trimesh's
    area-weighted `vertex_normals`.
    """

    path = Path(path)
    where = file if file is not None else path
    if not path.is_file():
        raise _fail(f"mesh file not found: {path}", where, field)
    # trimesh logs what it tries on a damaged file (tracebacks included); with no logging set up Python would print
    # that on stderr, so give its loggers a handler that drops it while loading (set-up logging still gets it).
    quiet = logging.NullHandler()
    logging.getLogger("trimesh").addHandler(quiet)
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as e:  # trimesh raises many kinds for unreadable files
        raise _fail(f"cannot read mesh {path}: {e}".splitlines()[0], where, field) from None
    finally:
        logging.getLogger("trimesh").removeHandler(quiet)
    if isinstance(loaded, trimesh.Scene) and len(loaded.graph.nodes_geometry) == 1:
        # One untransformed mesh (e.g. a GLB): take it as it is, keeping the normals its file stored
        # (Scene.dump() copies the geometry and drops them).
        transform, name = loaded.graph[loaded.graph.nodes_geometry[0]]
        if np.allclose(transform, np.eye(4)) and isinstance(loaded.geometry.get(name), trimesh.Trimesh):
            loaded = loaded.geometry[name]
    if isinstance(loaded, trimesh.Scene):
        parts = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        if not parts:
            raise _fail(f"no triangles in mesh {path}", where, field)
        loaded = trimesh.util.concatenate(parts) if len(parts) > 1 else parts[0]
    if not isinstance(loaded, trimesh.Trimesh):
        raise _fail(f"no triangles in mesh {path} (got {type(loaded).__name__})", where, field)
    file_normals = loaded._cache.cache.get("vertex_normals")  # normals the file itself stored
    vertices = np.asarray(loaded.vertices, np.float64)
    faces = np.asarray(loaded.faces, np.int64)
    if len(faces) == 0 or len(vertices) == 0:
        raise _fail(f"mesh {path} is empty (no triangles)", where, field)
    in_range = np.all(np.abs(vertices) <= FLOAT32_MAX, axis=1)  # False for NaN too
    if not np.all(in_range):
        bad = int(np.argmax(~in_range))
        raise _fail(f"mesh {path} has non-finite vertex coordinates in float32, which diffwash computes in "
                    f"(vertex {bad}: {vertices[bad].tolist()})", where, field)  # fmt: skip
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices):
        raise _fail(f"mesh {path} has faces that name vertices it does not have", where, field)
    normals = None
    if file_normals is not None and np.shape(file_normals) == vertices.shape:
        n = np.asarray(file_normals, np.float64)
        length = np.linalg.norm(n, axis=1)
        if np.all(np.isfinite(n)) and np.all(length > 1e-12):
            normals = n / length[:, None]
    if normals is None:
        normals = np.asarray(loaded.vertex_normals, np.float64)
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        normals = np.where(length > 1e-12, normals / np.maximum(length, 1e-300), [0.0, 0.0, 1.0])
    closed = bool(loaded.is_watertight) and bool(loaded.is_winding_consistent)
    return Mesh(vertices=vertices, faces=faces.astype(np.int32), normals=normals, closed=closed)


def _pigment(spec: Any, key: str, file: Any, base: Path) -> _pigments.Pigment:
    if isinstance(spec, str):
        spec = {"pigment": spec}
    if not isinstance(spec, dict):
        raise _fail('must be {"pigment": NAME_OR_FILE} or {"K": [...], "S": [...]}', file, key)
    if "pigment" in spec:
        _check_keys(spec, {"pigment", "name"}, file, f"{key}.")
        ref = spec["pigment"]
        if not isinstance(ref, str) or not ref:
            raise _fail("must be a pigment name or a pigment file", file, f"{key}.pigment")
        candidate = base / ref
        try:
            if ref.lower().endswith(".json") or candidate.is_file():
                return _pigments.load(candidate, name=spec.get("name"))
            return _pigments.load(ref)
        except DiffwashError as e:
            if e.file is not None:
                raise
            raise _fail(e.problem, file, f"{key}.pigment") from None
    if "K" in spec or "S" in spec:
        _check_keys(spec, {"K", "S", "name", "density", "staining", "granularity"}, file, f"{key}.")
        return _pigments.parse({"name": key, **spec}, file=file, where=key)
    raise _fail('needs "pigment" (a name or file) or "K" and "S"', file, key)


def _parse_size(data: dict, file: str | os.PathLike | None, size: tuple[int, int] | None) -> tuple[int, int]:
    """The image's (width, height): `size` (from --size) over the file's `image` object, checked."""
    image = _object(data, "image", file, required=False)
    _check_keys(image, {"width", "height"}, file, "image.")
    if size is not None:
        width, height = size
        wfield = hfield = "--size"
    else:
        width, height = image.get("width", 512), image.get("height", 512)
        wfield, hfield = "image.width", "image.height"
    for v, f in ((width, wfield), (height, hfield)):
        if not isinstance(v, int) or isinstance(v, bool):
            raise _fail(f"must be a whole number of pixels, got {v!r}", file, f)
        if not 1 <= v <= MAX_IMAGE_SIDE:
            raise _fail(f"must be between 1 and {MAX_IMAGE_SIDE} pixels, got {v}", file, f)
    return int(width), int(height)


def _parse_camera(cam: dict, mesh: Mesh, file: str | os.PathLike | None) -> Camera:
    """The `camera` object, checked; near and far default to the mesh's bounding sphere."""
    _check_keys(cam, _CAMERA_KEYS, file, "camera.")
    eye = _vec3(cam, "eye", file, "camera.eye")
    target = _vec3(cam, "target", file, "camera.target")
    up = _vec3(cam, "up", file, "camera.up", default=[0.0, 1.0, 0.0])
    fov_y = _number(cam, "fov_y", file, "camera.fov_y", default=40.0, lo=0.0, lo_open=True)
    if fov_y >= 180:
        raise _fail(f"must be below 180 degrees, got {fov_y}", file, "camera.fov_y")
    view = target - eye
    dist = float(np.linalg.norm(view))
    if not dist <= FLOAT32_MAX:
        raise _fail(f"is {dist:g} from camera.eye: out of float32 range", file, "camera.target")
    if dist <= 1e-9 * max(1.0, float(np.linalg.norm(eye))):
        raise _fail("camera.eye and camera.target are the same point: no view direction", file, "camera.target")
    if np.linalg.norm(up) == 0 or np.linalg.norm(np.cross(view / dist, up / np.linalg.norm(up))) < 1e-6:
        raise _fail("is parallel to the view direction (target - eye): the camera's roll is undefined", file, "camera.up")
    centre = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
    radius = float(np.max(np.linalg.norm(mesh.vertices - centre, axis=1)))
    depth_to_centre = float(np.dot(centre - eye, view / dist))
    default_far = max(depth_to_centre + radius, 1e-3) * 1.01 + 1e-6
    default_near = max(depth_to_centre - radius, default_far * 1e-3) * 0.99
    near = _number(cam, "near", file, "camera.near", default=default_near, lo=0.0, lo_open=True)
    far = _number(cam, "far", file, "camera.far", default=max(default_far, near * 1.01))
    if far <= near:
        raise _fail(f"must be greater than camera.near ({near}), got {far}", file, "camera.far")
    return Camera(eye=eye, target=target, up=up, fov_y=np.float64(fov_y), near=np.float64(near), far=np.float64(far))


def _parse_constants(data: dict, file: str | os.PathLike | None) -> dict[str, np.float64]:
    """The shading constants (gain, bias, thickness constants, shininess), checked against their ranges."""
    ranges = {"gain": (0, 1), "bias": (0, 1), "wash_reduction": (0, 1)}
    consts = {}
    for key, default in DEFAULT_CONSTANTS.items():
        lo, hi = ranges.get(key, (0, None))
        consts[key] = np.float64(_number(data, key, file, key, default=default, lo=lo, hi=hi))
    for key in ("gain", "bias"):
        if not 0 < consts[key] < 1:
            raise _fail(f"must be strictly between 0 and 1, got {float(consts[key])}", file, key)
    wash_max = float(consts["k_specular"] * consts["k_wash"])
    if not wash_max <= FLOAT32_MAX:  # the thickest wash, the LUT's wash_max: each factor fits float32, the product not
        raise _fail(f"k_specular x k_wash = {wash_max:g} (the thickest wash) is out of float32 range", file, "k_wash")
    return consts


def parse_scene(
    data: Any,
    *,
    file: str | os.PathLike | None = None,
    base: str | os.PathLike | None = None,
    shading: str | None = None,
    size: tuple[int, int] | None = None,
) -> Scene:
    """Make a `Scene` from parsed scene JSON. `base` resolves relative paths.

    `shading` and `size` (width, height) override the file's.
    """
    if not isinstance(data, dict):
        raise _fail(f"a scene must be a JSON object, got {type(data).__name__}", file)
    base = Path(base) if base is not None else (Path(file).parent if file is not None else Path("."))
    _check_keys(data, _TOP_KEYS, file)

    width, height = _parse_size(data, file, size)
    if "mesh" not in data:
        raise _fail("missing key", file, "mesh")
    if not isinstance(data["mesh"], str) or not data["mesh"]:
        raise _fail("must be the path of a mesh file", file, "mesh")
    mesh = load_mesh(base / data["mesh"], field="mesh", file=file)
    camera = _parse_camera(_object(data, "camera", file), mesh, file)
    light = _object(data, "light", file)
    _check_keys(light, {"direction"}, file, "light.")
    direction = _vec3(light, "direction", file, "light.direction")
    if np.linalg.norm(direction) == 0:
        raise _fail("must not be the zero vector", file, "light.direction")
    mode = shading if shading is not None else data.get("shading", "per-pixel")
    if mode not in SHADING_MODES:
        raise _fail(f"must be one of {', '.join(SHADING_MODES)}, got {mode!r}", file, "shading")
    backfaces = data.get("backfaces", "auto")
    if backfaces not in BACKFACE_MODES:
        raise _fail(f"must be one of {', '.join(BACKFACE_MODES)}, got {backfaces!r}", file, "backfaces")
    for key in ("wash", "unlit"):
        if key not in data:
            raise _fail("missing key", file, key)
    wash = _pigment(data["wash"], "wash", file, base)
    unlit = _pigment(data["unlit"], "unlit", file, base)
    paper = _vec3(data, "paper", file, "paper", default=DEFAULT_PAPER, nonneg=True)
    if np.any(paper > 1):
        raise _fail(f"is a reflectance and must be within [0, 1], got {paper.tolist()}", file, "paper")
    consts = _parse_constants(data, file)

    params = Params(wash=wash, unlit=unlit, paper=paper, light=direction, **consts)
    return Scene(
        mesh=mesh,
        camera=camera,
        params=params,
        width=int(width),
        height=int(height),
        shading=mode,
        backfaces=backfaces,
        path=None if file is None else os.fspath(file),
    )


def load_scene(
    path: str | os.PathLike, *, shading: str | None = None, size: tuple[int, int] | None = None
) -> Scene:
    """Load and validate a scene file.

    **Arguments:**

    - `path`: the scene JSON (format: module docstring, docs/scene-format.md).
    - `shading`: `"per-pixel"` or `"per-vertex"`, overriding the file's.
    - `size`: `(width, height)`, overriding the file's image size.

    **Returns:**

    The `Scene`. Bad input raises `DiffwashError` naming the file and the field.
    """
    return parse_scene(read_json(path), file=path, base=Path(path).parent, shading=shading, size=size)


def _floats(v: Any) -> Any:
    a = np.asarray(v, np.float64)
    return a.tolist() if a.ndim else float(a)


def scene_to_dict(scene: Scene, params: Params | None = None, *, relative_to: str | os.PathLike | None = None) -> dict:
    """The scene (with `params`, default the scene's) as scene-file JSON.

    Pigments are written as explicit K and S (with their names), so a fitted
    scene needs no pigment library. The mesh path is taken from the scene's own
    file and made relative to `relative_to` (the folder the JSON will live in).
    """
    p = scene.params if params is None else params
    out: dict[str, Any] = {}
    if scene.path is not None:
        src = read_json(scene.path)
        mesh_path = (Path(scene.path).parent / src["mesh"]).resolve()
        folder = Path(relative_to).resolve() if relative_to is not None else Path(scene.path).parent.resolve()
        try:
            out["mesh"] = os.path.relpath(mesh_path, folder)
        except ValueError:  # another drive (Windows)
            out["mesh"] = str(mesh_path)
        if "meta" in src:
            out["meta"] = src["meta"]
    out["image"] = {"width": scene.width, "height": scene.height}
    cam = scene.camera
    out["camera"] = {
        "eye": _floats(cam.eye),
        "target": _floats(cam.target),
        "up": _floats(cam.up),
        "fov_y": _floats(cam.fov_y),
        "near": _floats(cam.near),
        "far": _floats(cam.far),
    }
    out["light"] = {"direction": _floats(p.light)}
    out["shading"] = scene.shading
    out["backfaces"] = scene.backfaces
    out["paper"] = _floats(p.paper)
    for key in ("wash", "unlit"):
        pig = getattr(p, key)
        out[key] = {"name": pig.name, "K": _floats(pig.K), "S": _floats(pig.S)}
    for key in DEFAULT_CONSTANTS:
        out[key] = _floats(getattr(p, key))
    for k, v in out.items():
        if isinstance(v, float) and not math.isfinite(v):
            raise DiffwashError(f"is not finite ({v}); refusing to write the scene", field=k)
    return out


def referenced_files(path: str | os.PathLike) -> list[Path]:
    """The files a scene file names (its mesh, its pigment files), for commands that must not overwrite them.

    Best effort: a scene that cannot be read names none (`load_scene` says why).
    """
    try:
        data = read_json(path)
    except DiffwashError:
        return []
    if not isinstance(data, dict):
        return []
    base = Path(path).parent
    found = [base / data["mesh"]] if isinstance(data.get("mesh"), str) and data["mesh"] else []
    for key in ("wash", "unlit"):
        spec = data.get(key)
        ref = spec.get("pigment") if isinstance(spec, dict) else spec
        if isinstance(ref, str) and ref and (base / ref).is_file():
            found.append(base / ref)
    return found


def save_scene(path: str | os.PathLike, scene: Scene, params: Params | None = None) -> None:
    """Write `scene` (with `params`) as a scene file at `path`, atomically."""
    write_json(path, scene_to_dict(scene, params, relative_to=Path(path).parent))
