"""Scene files: JSON that names a mesh, a camera, a light, two pigments and the constants.

```
{"mesh": "knot.ply",                       // relative to the scene file; any format trimesh loads
 "image": {"width": 512, "height": 512},
 "camera": {"eye": [0,0,3], "target": [0,0,0], "up": [0,1,0], "fov_y": 40},
 "light": {"direction": [1,1,1]},          // towards the light, world space
 "shading": "per-pixel",                   // or "per-vertex"
 "paper": [0.92, 0.90, 0.84],              // linear reflectance of the paper
 "wash": {"pigment": "Quinacridone Rose"}, // or {"K": [...], "S": [...]}, or a pigment file, or
                                           // {"library": "paints.json", "mix": {"P1": 0.6, "P4": 0.4}}
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import equinox as eqx
import numpy as np
from jaxtyping import Float, Int

from . import pigments as _pigments
from ._camera import Camera
from ._errors import DiffwashError
from ._io import FLOAT32_MAX, check_input_file, read_json, write_json
from ._lazy import lazy
from ._mixture import Mixture, mixture
from ._scene_schema import BACKFACE_MODES, MAX_IMAGE_SIDE, SceneFile
from ._schema import validate
from ._watercolour import Watercolour, parse_watercolour, watercolour_files, watercolour_to_dict
from .library import Library, load_library
from .shading import DEFAULT_CONSTANTS, DEFAULT_PAPER, SHADING_MODES, Params
from .spectral import Observation

trimesh = lazy("trimesh")

__all__ = ["Mesh", "Scene", "load_scene", "load_mesh", "parse_scene", "save_scene", "referenced_files", "MAX_IMAGE_SIDE"]



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
    - `watercolour`: the watercolour look (`diffwash._watercolour.Watercolour`,
      from the file's `"watercolour"` object), or None for the plain model.
    """

    mesh: Mesh
    camera: Camera
    params: Params
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    shading: str = eqx.field(static=True, default="per-pixel")
    backfaces: str = eqx.field(static=True, default="auto")
    path: str | None = eqx.field(static=True, default=None)
    watercolour: Watercolour | None = None

    @property
    def cull_backfaces(self) -> bool:
        """Whether back-facing triangles are hidden."""
        return self.backfaces == "cull" or (self.backfaces == "auto" and self.mesh.closed)


def _fail(msg: str, file: Any, field: str | None = None) -> DiffwashError:
    return DiffwashError(msg, file=file, field=field)


def load_mesh(path: str | os.PathLike, *, field: str = "mesh", file: Any = None) -> Mesh:
    """Load a triangle mesh with trimesh (any format it reads), validated.

    Vertex normals are the file's own where it has them, else trimesh's
    area-weighted `vertex_normals`.
    """

    path = Path(path)
    where = file if file is not None else path
    if not os.path.lexists(path):
        raise _fail(f"mesh file not found: {path}", where, field)
    check_input_file(path, file=file, field=field)
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
    if vertices.ndim != 2 or vertices.shape[1] != 3:  # e.g. an OBJ whose `v` lines hold two numbers
        raise _fail(f"mesh {path} has vertices of {vertices.shape[-1]} coordinates, not 3 (x, y, z)", where, field)
    in_range = np.all(np.abs(vertices) <= FLOAT32_MAX, axis=1)  # False for NaN too
    if not np.all(in_range):
        bad = int(np.argmax(~in_range))
        raise _fail(f"mesh {path} has non-finite vertex coordinates in float32, which diffwash computes in "
                    f"(vertex {bad}: {vertices[bad].tolist()})", where, field)  # fmt: skip
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 or faces.max() >= len(vertices):
        raise _fail(f"mesh {path} has faces that name vertices it does not have", where, field)
    v = vertices[faces]
    if not np.any(np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1) > 0):
        raise _fail(f"mesh {path} has no triangle of non-zero area (each of its {len(faces)} is a point or a "
                    f"line): nothing to draw", where, field)  # fmt: skip
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
    """A glaze's three-channel pigment (`spec` checked by `SceneFile`): by name, from a file, or K and S."""
    if isinstance(spec, str):
        spec = {"pigment": spec}
    if "pigment" in spec:
        ref = spec["pigment"]
        candidate = base / ref
        try:
            if ref.lower().endswith(".json") or candidate.is_file():
                return _pigments.load(candidate, name=spec.get("name"))
            return _pigments.load(ref)
        except DiffwashError as e:
            if e.file is not None:
                raise
            raise _fail(e.problem, file, f"{key}.pigment") from None
    return _pigments.parse({"name": key, **spec}, file=file, where=key)


#: How far a mix's proportions may sum from 1.
_SUM_TOLERANCE = 1e-6


@dataclass(frozen=True)
class _Glaze:
    """A parsed glaze: its pigment or mixture, and how its bands are seen (None: three sRGB channels)."""

    pigment: _pigments.Pigment | Mixture
    observation: Observation | None
    library: Library | None = None
    source: str | None = None  # the library as the scene names it


def _load_library(ref: Any, file: Any, field: str, base: Path, cache: dict) -> tuple[Library, Path]:
    """The library file `ref` (relative to the scene), read once per parse; errors name the scene's field."""
    path = base / ref
    key = os.path.abspath(path)
    if key not in cache:
        if not os.path.lexists(path):
            raise _fail(f"no such library file: {ref}", file, field)
        try:
            lib = load_library(path)
        except DiffwashError as e:
            where = f"{e.field}: " if e.field else ""
            raise _fail(f"{ref}: {where}{e.problem}", file, field) from None
        if lib.k2 != 0:
            raise _fail(f"{ref}: surface.k2 = {lib.k2:g}, but scenes do not model Saunderson's surface term; use a "
                        "library fitted without --surface saunderson", file, field)  # fmt: skip
        cache[key] = lib
    return cache[key], path


def _proportions(mix: dict, file: Any, field: str) -> dict[str, float]:
    """A mix's `{NAME: proportion}` (each >= 0, each name once: `SceneFile`), summing to 1."""
    out = {name: float(v) for name, v in mix.items()}
    total = sum(out.values())
    if abs(total - 1) > _SUM_TOLERANCE:
        raise _fail(f"proportions must sum to 1, got {' + '.join(f'{v:g}' for v in out.values())} = {total:g}",
                    file, field)  # fmt: skip
    return out


def _library_glaze(spec: dict, key: str, file: Any, base: Path, cache: dict) -> _Glaze:
    """`{"library": FILE, "pigment": NAME}` or `{"library": FILE, "mix": {...}}`, with an optional `amount`."""
    lib, path = _load_library(spec["library"], file, f"{key}.library", base, cache)
    if "pigment" in spec:
        name = spec["pigment"]
        props, fields = {name: 1.0}, {name: f"{key}.pigment"}
    else:
        props = _proportions(spec["mix"], file, f"{key}.mix")
        fields = {n: f"{key}.mix.{n}" for n in props}
    known = {n.lower() for n in lib.names}
    for n in props:
        if n.lower() not in known:
            close = difflib.get_close_matches(n, list(lib.names), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise _fail(f"no pigment {n!r} in {spec['library']} (it has {', '.join(lib.names)}){hint}", file, fields[n])
    amount = None if spec.get("amount") is None else float(spec["amount"])  # null: declared as the default
    obs = lib.observation if lib.spectral else None
    return _Glaze(mixture(lib, props, amount, source=path), obs, lib, spec["library"])


def _glaze(spec: Any, key: str, file: Any, base: Path, cache: dict) -> _Glaze:
    if isinstance(spec, dict) and "library" in spec:
        return _library_glaze(spec, key, file, base, cache)
    return _Glaze(_pigment(spec, key, file, base), None)


def _bands(g: _Glaze) -> str:
    if g.observation is None:
        return "a 3-channel pigment" if g.library is None else f"from {g.source} (sRGB channels)"
    obs = g.observation
    return (f"spectral ({len(obs.bands)} bands, {obs.wavelengths[0]:g}-{obs.wavelengths[-1]:g} nm, {obs.illuminant}, "
            f"{obs.observer}, of {g.source})")  # fmt: skip


def _parse_glazes(data: dict, file: Any, base: Path, cache: dict) -> tuple[_Glaze, _Glaze]:
    """The `wash` and `unlit` glazes, seen alike (both three channels, or both on one spectral grid)."""
    wash = _glaze(data["wash"], "wash", file, base, cache)
    unlit = _glaze(data["unlit"], "unlit", file, base, cache)
    seen = [None if g.observation is None else g.observation.describe() for g in (wash, unlit)]
    if seen[0] != seen[1]:
        raise _fail(f"is {_bands(unlit)} but wash is {_bands(wash)}: both glazes must be seen alike (both "
                    "3-channel, or spectral on the same bands, illuminant and observer)", file, "unlit")  # fmt: skip
    spectral = wash.observation is not None
    if isinstance(wash.pigment, Mixture) or isinstance(unlit.pigment, Mixture):
        if data.get("watercolour") not in (None, False):
            raise _fail("the watercolour look takes pigments ({\"pigment\": ...} or K and S), not library paints "
                        f"({'spectral' if spectral else 'mixed'} glazes render with the plain model)", file,
                        "watercolour")  # fmt: skip
    return wash, unlit


def _ground(spec: dict, file: Any, base: Path, cache: dict, glazes: tuple[_Glaze, _Glaze]) -> tuple[np.ndarray, Observation]:
    """`{"ground": NAME}` (from the glazes' library) or `{"library": FILE, "ground": NAME}`."""
    if "library" in spec:
        lib, _ = _load_library(spec["library"], file, "paper.library", base, cache)
        source = spec["library"]
    else:
        g = next((g for g in glazes if g.library is not None), None)
        if g is None:
            raise _fail('needs "library" (the glazes are not library pigments)', file, "paper")
        lib, source = g.library, g.source
    name = spec["ground"]
    grounds = {k.lower(): v for k, v in lib.grounds.items()}
    if name.lower() not in grounds:
        raise _fail(f"no ground {name!r} in {source} (it has {', '.join(lib.grounds)})", file, "paper.ground")
    return np.asarray(grounds[name.lower()], np.float64), lib.observation


def _parse_paper(data: dict, file: Any, base: Path, cache: dict, glazes: tuple[_Glaze, _Glaze]) -> np.ndarray:
    """The paper on the glazes' bands: a list, a library ground, or the default."""
    obs = glazes[0].observation
    spec = data.get("paper")
    if spec is None and obs is not None:
        lib = glazes[0].library
        if "paper" not in {k.lower() for k in lib.grounds}:
            raise _fail(f'missing key: a spectral scene\'s paper is a ground of its library, {{"ground": NAME}} '
                        f"({glazes[0].source} has {', '.join(lib.grounds)})", file, "paper")  # fmt: skip
        spec = {"ground": "paper"}
    if isinstance(spec, dict):
        values, seen = _ground(spec, file, base, cache, glazes)
        if obs is None:  # a 3-channel scene over a measured ground: its colour
            return np.clip(np.asarray(seen.linear_srgb(values), np.float64), 0, 1)
        if seen.describe() != obs.describe():
            raise _fail(f"{spec.get('library')} is seen on other bands than the glazes", file, "paper.library")
        return values
    n = 3 if obs is None else len(obs.bands)
    paper = np.asarray(DEFAULT_PAPER if spec is None else spec, np.float64)  # numbers >= 0 (`SceneFile`)
    if len(paper) != n:
        raise _fail(f'must be {{"ground": NAME}} or a list of {n} reflectances >= 0 (one per '
                    f"{'channel' if obs is None else 'band of the glazes' + chr(39) + ' library'})", file, "paper")
    if obs is None and np.any(paper > 1):
        raise _fail(f"is a reflectance and must be within [0, 1], got {paper.tolist()}", file, "paper")
    return paper


def _parse_size(image: Any, file: str | os.PathLike | None, size: tuple[int, int] | None) -> tuple[int, int]:
    """The image's (width, height): `size` (from --size, checked here) over the file's `image` (`SceneFile`)."""
    if size is None:
        return image.width, image.height
    for v in size:
        if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= MAX_IMAGE_SIDE:
            raise _fail(f"must be whole numbers of pixels between 1 and {MAX_IMAGE_SIDE}, got {v!r}", file, "--size")
    return int(size[0]), int(size[1])


def _parse_camera(cam: Any, mesh: Mesh, file: str | os.PathLike | None) -> Camera:
    """The `camera` (its types and ranges checked by `SceneFile`): a view direction and an up that is not along it;
    near and far default to the mesh's bounding sphere."""
    eye, target, up = (np.asarray(v, np.float64) for v in (cam.eye, cam.target, cam.up))
    fov_y = cam.fov_y
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
    near = default_near if cam.near is None else cam.near
    far = max(default_far, near * 1.01) if cam.far is None else cam.far
    if far <= near:
        raise _fail(f"must be greater than camera.near ({near}), got {far}", file, "camera.far")
    return Camera(eye=eye, target=target, up=up, fov_y=np.float64(fov_y), near=np.float64(near), far=np.float64(far))


def _parse_constants(model: Any, file: str | os.PathLike | None) -> dict[str, np.float64]:
    """The shading constants (their ranges checked by `SceneFile`), whose product k_specular x k_wash fits float32."""
    consts = {key: np.float64(getattr(model, key)) for key in DEFAULT_CONSTANTS}
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
    model = validate(SceneFile, data, file, what="scene")  # keys, types, ranges, float32: before anything is read
    base = Path(base) if base is not None else (Path(file).parent if file is not None else Path("."))
    width, height = _parse_size(model.image, file, size)
    mesh = load_mesh(base / model.mesh, field="mesh", file=file)
    camera = _parse_camera(model.camera, mesh, file)
    direction = np.asarray(model.light.direction, np.float64)
    mode = shading if shading is not None else model.shading
    if mode not in SHADING_MODES:
        raise _fail(f"must be one of {', '.join(SHADING_MODES)}, got {mode!r}", file, "--shading")
    backfaces = model.backfaces
    libraries: dict = {}
    glazes = _parse_glazes(data, file, base, libraries)
    paper = _parse_paper(data, file, base, libraries, glazes)
    consts = _parse_constants(model, file)

    params = Params(wash=glazes[0].pigment, unlit=glazes[1].pigment, paper=paper, light=direction, **consts,
                    observation=glazes[0].observation)  # fmt: skip
    look = parse_watercolour(
        model.watercolour or None, file=file, base=base, mesh=mesh, params=params,
        pigment=lambda spec, key: _pigment(spec, key, file, base),
    )  # fmt: skip
    return Scene(
        mesh=mesh,
        camera=camera,
        params=params,
        width=int(width),
        height=int(height),
        shading=mode,
        backfaces=backfaces,
        path=None if file is None else os.fspath(file),
        watercolour=look,
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
        if scene.watercolour is not None:  # the look as written, with its (possibly fitted) values
            look = watercolour_to_dict(src.get("watercolour"), scene.watercolour)
            for effect in ("paper", "mix"):  # paths relative to the folder the JSON will live in
                path = look.get(effect, {}).get("image" if effect == "paper" else "map") if isinstance(look.get(effect), dict) else None
                if isinstance(path, str):
                    key = "image" if effect == "paper" else "map"
                    look[effect][key] = os.path.relpath((Path(scene.path).parent / path).resolve(), folder)
            out["watercolour"] = look
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
        if isinstance(pig, Mixture):  # library pigments: the library, named relative to the new file
            out[key] = pig.describe(relative_to if relative_to is not None else _folder(scene))
        else:
            out[key] = {"name": pig.name, "K": _floats(pig.K), "S": _floats(pig.S)}
    for key in DEFAULT_CONSTANTS:
        out[key] = _floats(getattr(p, key))
    for k, v in out.items():
        if isinstance(v, float) and not math.isfinite(v):
            raise DiffwashError(f"is not finite ({v}); refusing to write the scene", field=k)
    return out


def _folder(scene: Scene) -> str | None:
    return None if scene.path is None else os.fspath(Path(scene.path).parent)


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
    for key in ("wash", "unlit", "paper"):
        spec = data.get(key)
        refs = [spec.get("pigment"), spec.get("library")] if isinstance(spec, dict) else [spec]
        found += [base / ref for ref in refs if isinstance(ref, str) and ref and (base / ref).is_file()]
    return found + watercolour_files(data.get("watercolour"), base)


def save_scene(path: str | os.PathLike, scene: Scene, params: Params | None = None) -> None:
    """Write `scene` (with `params`) as a scene file at `path`, atomically."""
    write_json(path, scene_to_dict(scene, params, relative_to=Path(path).parent))
