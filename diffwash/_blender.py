"""The Blender target: a script that builds the scene in Blender, and a `.blend` where `bpy` is installed.

`diffwash export SCENE --target blender -o DIR` writes, beside the plain model's files,

- `blender_scene.py`: a script for a fresh Blender (4.2; `python blender_scene.py`
  where Blender's `bpy` module is installed, or `blender -b -P blender_scene.py --`).
  It builds the mesh, the camera, the paper as the world's colour, and two
  materials from node groups named for diffwash: `diffwash watercolour`
  (the thicknesses per pixel, then the LUT) and `diffwash LUT` (the LUT over
  the paper, read at a (wash, unlit) thickness; the per-vertex material reads
  the thicknesses that the `diffwash per-vertex thickness` geometry-nodes
  modifier stores at the vertices). With `--render OUT.png` it renders the
  scene at its size and camera (`--help` lists the options), with `--save
  OUT.blend` it saves the file.
- `blender_data.npz`: what the script reads: the mesh (vertices, faces, vertex
  normals) and the baked LUT in linear values.
- `scene.blend` where `bpy` is importable here: the script's scene, saved, the
  LUT packed into it.

The shading is not written out here: `diffwash.shading.thicknesses` (with the
safe normalisations of the shaders' `main`s) is traced on symbolic values
(`diffwash._xp`), the same trace that gives the GLSL, and the trace is lowered
to a program of Blender's Math, Vector Math and Combine/Separate XYZ nodes
(`node_program`): the constants (epsilons, the `0^0 = 1` power, the bias and
gain clamps) are the model's. The script only instantiates that program as a
node group, once in the material (per pixel) and once in geometry nodes (per
vertex). `evaluate_program` runs a program in NumPy, which the tests hold
against the model without Blender.
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from . import look as wl
from . import shading
from ._choices import BLENDER_LEAVES_OUT
from ._errors import DiffwashError, FailureError
from ._glsl import _symbol, _uniform_params
from ._look_glsl import MIX_LUT_SIZE, mix_lut, mix_lut_range
from ._version import __version__
from ._xp import Expr, _memo
from .lut import Lut
from .shading import CONSTANTS

__all__ = ["BLENDER_FILES", "BLENDER_SCRIPT", "BLENDER_DATA", "BLENDER_FILE", "node_program", "thickness_program",
           "look_programs", "leaves_out", "evaluate_program", "blender_config", "blender_script", "write_blender",
           "bpy_available"]  # fmt: skip

#: The script, its data, and the `.blend` written where `bpy` is importable.
BLENDER_SCRIPT, BLENDER_DATA, BLENDER_FILE = "blender_scene.py", "blender_data.npz", "scene.blend"
BLENDER_FILES = (BLENDER_SCRIPT, BLENDER_DATA, BLENDER_FILE)
#: Seconds the `.blend` may take to build (a fresh Blender process: import, mesh, nodes, save).
_SAVE_TIMEOUT_S = 600

# --- lowering a traced expression to Blender's nodes ------------------------------------------------

#: Scalar operators and functions of the trace -> Blender Math node operations.
_MATH = {"+": "ADD", "-": "SUBTRACT", "*": "MULTIPLY", "/": "DIVIDE", "min": "MINIMUM", "max": "MAXIMUM",
         "exp": "EXPONENT", "sqrt": "SQRT", "abs": "ABSOLUTE", "floor": "FLOOR", "sin": "SINE", "cos": "COSINE",
         "pow": "POWER", "log": "LOGARITHM"}  # fmt: skip
#: Vector operators and functions -> Vector Math node operations (the others go channel by channel).
_VECTOR = {"+": "ADD", "-": "SUBTRACT", "*": "MULTIPLY", "/": "DIVIDE", "min": "MINIMUM", "max": "MAXIMUM",
           "abs": "ABSOLUTE", "floor": "FLOOR", "sin": "SINE", "cos": "COSINE"}  # fmt: skip
_BINARY = {"{0} + {1}": "+", "{0} - {1}": "-", "{0} * {1}": "*", "{0} / {1}": "/"}
_COMPARE = {"{0} < {1}": "<", "{0} > {1}": ">", "{0} <= {1}": "<=", "{0} >= {1}": ">=", "{0} == {1}": "==",
            "{0} != {1}": "!="}  # fmt: skip


class _Lowering:
    """Turns `Expr` DAGs into a list of nodes; each distinct sub-expression becomes nodes once."""

    def __init__(self, inputs: dict[str, int]):
        self.inputs = inputs  # the atoms that are the group's inputs, and their sizes
        self.nodes: list[dict[str, Any]] = []
        self.done: dict[int, Any] = {}

    def node(self, op: str, operation: str | None, args: list[Any], output: int = 0) -> dict[str, Any]:
        self.nodes.append({"op": op, "operation": operation, "inputs": args})
        return {"node": len(self.nodes) - 1, "output": output}

    def math(self, operation: str, *args: Any) -> dict[str, Any]:
        return self.node("math", operation, list(args))

    def vector(self, operation: str, *args: Any) -> dict[str, Any]:
        return self.node("vector", operation, list(args), 1 if operation == "DOT_PRODUCT" else 0)

    def widen(self, ref: Any, size: int) -> Any:
        if size == 1 or _size(ref) == size:
            return ref
        if "value" in ref:
            return {"value": [ref["value"]] * 3}
        return self.node("combine", None, [ref, ref, ref])

    def channels(self, ref: Any) -> list[Any]:
        if "value" in ref:
            v = ref["value"]
            return [{"value": x} for x in (v if isinstance(v, list) else [v] * 3)]
        sep = len(self.nodes)
        self.node("separate", None, [ref])
        return [{"node": sep, "output": i} for i in range(3)]

    def atom(self, e: Expr) -> Any:
        code = e.code
        if code in self.inputs:
            return {"input": code}
        if code in ("true", "false"):
            return {"value": 1.0 if code == "true" else 0.0}
        if code.startswith("vec3(") and code.endswith(")"):
            return {"value": [float(code[5:-1])] * 3}
        try:
            return {"value": float(code)}
        except ValueError:
            raise TypeError(f"the Blender lowering has no input named {code!r}") from None

    def ref(self, e: Expr) -> Any:
        if e.atom:
            return self.atom(e)
        if e.id not in self.done:
            args = [self.ref(a) for a in e.args]
            for a, r in zip(e.args, args):
                _annotate(r, a.size)
            self.done[e.id] = self.lower(e, args)
            _annotate(self.done[e.id], e.size)
        return self.done[e.id]

    def elementwise(self, fn: str, args: list[Any], size: int) -> Any:
        """A function of scalars, or of vectors (channel by channel where Vector Math lacks it)."""
        if size == 1:
            if fn == "log":  # Blender's Math log takes a base
                return self.math("LOGARITHM", args[0], {"value": math.e})
            return self.math(_MATH[fn], *args)
        args = [self.widen(a, size) for a in args]
        if fn in _VECTOR:
            return self.vector(_VECTOR[fn], *args)
        split = [self.channels(a) for a in args]
        parts = [self.elementwise(fn, [s[i] for s in split], 1) for i in range(3)]
        return self.node("combine", None, parts)

    def compare(self, op: str, a: Any, b: Any) -> Any:
        """A comparison as 1.0 or 0.0, exact (Blender's Compare has a tolerance; < and > have none)."""
        if op in ("<", ">"):
            return self.math("LESS_THAN" if op == "<" else "GREATER_THAN", a, b)
        lt, gt = self.math("LESS_THAN", a, b), self.math("GREATER_THAN", a, b)
        if op == "<=":
            return self.math("SUBTRACT", {"value": 1.0}, gt)
        if op == ">=":
            return self.math("SUBTRACT", {"value": 1.0}, lt)
        either = self.math("MAXIMUM", lt, gt)
        return either if op == "!=" else self.math("SUBTRACT", {"value": 1.0}, either)

    def select(self, c: Any, a: Any, b: Any, size: int) -> Any:
        """`c ? a : b` as `c a + (1 - c) b`: exact for c in {0, 1} and finite a, b (the model's branches are)."""
        not_c = self.math("SUBTRACT", {"value": 1.0}, c)
        if size == 1:
            return self.math("ADD", self.math("MULTIPLY", c, a), self.math("MULTIPLY", not_c, b))
        a, b = self.widen(a, 3), self.widen(b, 3)
        scaled = [self.node("vector", "SCALE", [v, {"value": [0.0] * 3}, {"value": [0.0] * 3}, s]) for v, s in ((a, c), (b, not_c))]
        return self.vector("ADD", *scaled)

    def lower(self, e: Expr, args: list[Any]) -> Any:
        code, size = e.code, e.size
        if size not in (1, 3):
            raise TypeError(f"the Blender lowering takes floats and vec3s, not a {e.type} ({code})")
        if code in _BINARY:
            return self.elementwise(_BINARY[code], args, size)
        if code in _COMPARE:
            if size != 1:
                raise TypeError(f"the Blender lowering compares floats only ({code})")
            return self.compare(_COMPARE[code], *args)
        if code == "-{0}":
            return self.elementwise("-", [{"value": 0.0}, args[0]], size)
        if code == "({0} ? {1} : {2})":
            return self.select(*args, size=size)
        if code == "({0} && {1})":
            return self.math("MULTIPLY", *args)
        if code == "({0} || {1})":
            return self.math("MAXIMUM", *args)
        if code == "!{0}":
            return self.math("SUBTRACT", {"value": 1.0}, args[0])
        if code == "vec3({0})":
            return self.widen(args[0], 3)
        if code.startswith("{0}.") and len(code) == 5:
            return self.channels(args[0])["xyz".index(code[-1])]
        fn = code.partition("(")[0]
        if fn == "clamp":
            return self.elementwise("min", [self.elementwise("max", args[:2], size), args[2]], size)
        if fn == "dot":
            return self.vector("DOT_PRODUCT", *args)
        if fn in _MATH:
            return self.elementwise(fn, args, size)
        raise TypeError(f"the Blender lowering has no node for {code!r}")


def _annotate(ref: Any, size: int) -> None:
    ref.setdefault("size", size)


def _size(ref: Any) -> int:
    if "value" in ref:
        return 3 if isinstance(ref["value"], list) else 1
    return ref.get("size", 1)


def node_program(fn: Callable[..., Any], inputs: dict[str, int], outputs: list[str]) -> dict[str, Any]:
    """`fn` traced on symbolic inputs and lowered to Blender nodes, as plain (JSON) data.

    **Arguments:**

    - `fn`: a function of `Expr`s (named as `inputs`, in order) returning one
      value per name of `outputs`; written against `diffwash._xp`'s namespace,
      as the model is.
    - `inputs`: name -> size (1: a float, 3: a vector) of the group's inputs.
    - `outputs`: names of the group's outputs.

    **Returns:**

    `{"inputs": [[name, size], ...], "outputs": {name: ref}, "nodes": [...]}`,
    where each node is `{"op": "math" | "vector" | "combine" | "separate",
    "operation": <Blender's enum>, "inputs": [ref, ...]}` and a ref is
    `{"input": name}`, `{"value": x}` (a float or three) or `{"node": i,
    "output": k}`. `diffwash/data/blender_scene.py` builds it; `evaluate_program`
    runs it.
    """
    _memo.clear()
    try:
        results = fn(*(_symbol(name, size) for name, size in inputs.items()))
        results = results if isinstance(results, tuple) else (results,)
        lowering = _Lowering(inputs)
        refs = {name: lowering.ref(r) if isinstance(r, Expr) else {"value": float(r)} for name, r in zip(outputs, results)}
    finally:
        _memo.clear()
    return {"inputs": [[k, v] for k, v in inputs.items()], "outputs": refs, "nodes": lowering.nodes}


#: The inputs of the thickness group: the interpolated normal (turned for drawn back faces), the direction
#: towards the eye (any length), and the scene's light direction and constants.
_THICKNESS_INPUTS = {"normal": 3, "view": 3, "light_direction": 3, **{k: 1 for k in CONSTANTS}}


def _thickness_at_point(normal: Expr, view: Expr, light: Expr, *constants: Expr) -> tuple[Expr, Expr]:
    """The shaders' per-point shading: normalise N, L and V, then `shading.thicknesses`.

    The constants reach the model as the leaves of the shaders' uniform `Params` (symbols of the same names as
    `constants`, which the lowering maps to the group's inputs by name).
    """
    p = _uniform_params()
    n, l_, v = (shading.safe_normalize(x) for x in (normal, light, view))
    return shading.thicknesses(n, l_, v, p)


def thickness_program() -> dict[str, Any]:
    """`shading.thicknesses` at a point, lowered to Blender nodes (`node_program`): outputs `wash`, `unlit`."""
    return node_program(_thickness_at_point, _THICKNESS_INPUTS, ["wash", "unlit"])


def evaluate_program(program: dict[str, Any], values: dict[str, Any]) -> dict[str, np.ndarray]:
    """Run a `node_program` in NumPy on arrays (vectors on the last axis), as Blender's nodes compute.

    Blender's Math nodes divide safely (0 where the divisor is 0), take the
    square root and logarithm of non-positive numbers as 0; so does this.
    """
    done: list[Any] = []

    def get(ref: Any) -> Any:
        if "input" in ref:
            return np.asarray(values[ref["input"]], np.float64)
        if "value" in ref:
            return np.asarray(ref["value"], np.float64)
        out = done[ref["node"]]
        return out[ref["output"]] if isinstance(out, tuple) else out

    for node in program["nodes"]:
        args = [get(r) for r in node["inputs"]]
        done.append(_evaluate_node(node["op"], node["operation"], args))
    return {name: get(ref) for name, ref in program["outputs"].items()}


def _safe_divide(a: Any, b: Any) -> Any:
    return np.where(b != 0, a / np.where(b != 0, b, 1), 0.0)


def _evaluate_node(op: str, operation: str | None, args: list[Any]) -> Any:
    if op == "combine":
        return np.stack(np.broadcast_arrays(*args), axis=-1)
    if op == "separate":
        return tuple(args[0][..., i] for i in range(3))
    if op == "vector":
        a = args[0]
        if operation == "DOT_PRODUCT":
            return (None, np.sum(a * args[1], axis=-1))
        if operation == "SCALE":
            return a * np.asarray(args[3])[..., None]
    a = args[0]
    b = args[1] if len(args) > 1 else None
    with np.errstate(all="ignore"):
        table = {
            "ADD": lambda: a + b, "SUBTRACT": lambda: a - b, "MULTIPLY": lambda: a * b, "DIVIDE": lambda: _safe_divide(a, b),
            "MINIMUM": lambda: np.minimum(a, b), "MAXIMUM": lambda: np.maximum(a, b), "ABSOLUTE": lambda: np.abs(a),
            "EXPONENT": lambda: np.exp(a), "SQRT": lambda: np.where(a > 0, np.sqrt(np.maximum(a, 0)), 0.0),
            "LOGARITHM": lambda: np.where(a > 0, np.log(np.where(a > 0, a, 1)) / np.log(b), 0.0),
            "LESS_THAN": lambda: (a < b).astype(np.float64), "GREATER_THAN": lambda: (a > b).astype(np.float64),
            "FLOOR": lambda: np.floor(a), "SINE": lambda: np.sin(a), "COSINE": lambda: np.cos(a),
            "POWER": lambda: np.power(a, b),
        }  # fmt: skip
        return table[operation]()


# --- the script and its data ------------------------------------------------------------------------


def leaves_out(scene: Any) -> list[str]:
    """The effects of the scene's look that shader nodes cannot carry (`diffwash.BLENDER_LEAVES_OUT`, in its
    order); the look's other effects are per pixel and are carried (`look_programs`)."""
    wc = scene.watercolour
    return [] if wc is None else [k for k in BLENDER_LEAVES_OUT if k in wc.effects]


#: The per-pixel inputs of the look's image terms in Blender (`look_programs`): the thicknesses, the per-vertex mix
#: and stroke value, and the screen tile's channels.
_LOOK_TERMS = ("wash", "unlit", "mix", "stroke", "paper", "turbulence_wash", "dispersion_wash", "turbulence_unlit",
               "dispersion_unlit")  # fmt: skip


def look_programs(scene: Any) -> dict[str, Any]:
    """The watercolour look's per-pixel arithmetic lowered to Blender nodes (`node_program`), the scene's look values
    and pigments in it as constants: `terms` (`diffwash.look.pixel_terms` at a pixel whose local mean is its own
    value: no edge darkening; outputs `wash`, `unlit`) and `relief` (`diffwash.look.paper_shading`: `rgb`)."""
    wc = scene.watercolour
    look, pigments = wc.look, wc.pigments

    def terms(w, u, m, stroke, paper, tw, dw, tu, du):
        return wl.pixel_terms(w, u, w, u, m, stroke, paper, tw, dw, tu, du, look, pigments)

    return {"terms": node_program(terms, dict.fromkeys(_LOOK_TERMS, 1), ["wash", "unlit"]),
            "relief": node_program(lambda rgb, shade: wl.paper_shading(rgb, shade, look.paper_shading),
                                   {"rgb": 3, "shade": 1}, ["rgb"])}  # fmt: skip


def _look_config(scene: Any, p: Any) -> dict[str, Any]:
    wash_max, unlit_max = mix_lut_range(p)
    return {**look_programs(scene), "channels": list(wl.CHANNELS), "tile": list(np.asarray(scene.watercolour.screen).shape[:2]),
            "mix_lut": {"size": list(MIX_LUT_SIZE), "wash_max": wash_max, "unlit_max": unlit_max},
            "not_carried": leaves_out(scene)}  # fmt: skip


def _camera_to_world(camera: Any) -> list[list[float]]:
    """The camera's object matrix in Blender: the inverse of diffwash's view matrix (both look down -z, y up)."""
    return np.linalg.inv(np.asarray(camera.view(), np.float64)).tolist()


def blender_config(scene: Any, lut: Lut, params: Any = None) -> dict[str, Any]:
    """What `blender_scene.py` embeds: size, camera, shading mode, back faces, the constants, the LUT's range, the program."""
    if lut.kind != "colour":
        raise DiffwashError("the Blender target draws the colour LUT; --rt (R and T over a paper uniform) is for "
                            "the GLSL targets", field="kind")  # fmt: skip
    p = scene.params if params is None else params
    cam = scene.camera
    return {
        "diffwash_version": __version__,
        "title": str(scene.path or "scene"),
        "width": scene.width,
        "height": scene.height,
        "shading": scene.shading,
        "cull_backfaces": bool(scene.cull_backfaces),
        "camera": {
            "matrix_world": _camera_to_world(cam),
            "fov_y": float(np.asarray(cam.fov_y)),
            "near": float(np.asarray(cam.near)),
            "far": float(np.asarray(cam.far)),
        },
        "paper": [float(x) for x in np.asarray(shading.paper_colour(p), np.float64).reshape(3)],
        "light_direction": [float(x) for x in np.asarray(p.light, np.float64).reshape(3)],
        "constants": {k: float(np.asarray(getattr(p, k))) for k in CONSTANTS},
        "lut": {"size": list(lut.size), "wash_max": float(lut.wash_max), "unlit_max": float(lut.unlit_max)},
        "thickness": thickness_program(),
        "look": None if scene.watercolour is None else _look_config(scene, p),
    }


def _template() -> str:
    return (resources.files("diffwash") / "data" / "blender_scene.py").read_text(encoding="utf-8")


def blender_script(scene: Any, lut: Lut, params: Any = None) -> str:
    """`blender_scene.py` for `scene` drawn with `lut`: the script's text (its data is `blender_data.npz`)."""
    blob = json.dumps(blender_config(scene, lut, params), separators=(",", ":"))
    return _template().replace('CONFIG = "__CONFIG__"', f"CONFIG = json.loads({blob!r})").replace("__VERSION__", __version__)


def bpy_available() -> bool:
    """Whether Blender's Python module (`pip install 'diffwash[blender]'`) is importable here."""
    return importlib.util.find_spec("bpy") is not None


def write_blender(folder: Path, scene: Any, lut: Lut, *, params: Any = None, blend: bool | None = None) -> list[Path]:
    """Write the script and its data into `folder`, and the `.blend` where `bpy` is importable (`blend`: force)."""
    (folder / BLENDER_SCRIPT).write_text(blender_script(scene, lut, params), encoding="utf-8")
    mesh = scene.mesh
    look = {}
    if scene.watercolour is not None:  # the look's mix LUT, screen tile, and per-vertex mix and stroke value
        wc, n = scene.watercolour, len(np.asarray(mesh.vertices))
        look = {"mix_lut": mix_lut(scene, scene.params if params is None else params)[0],
                "screen": np.asarray(wc.screen, np.float32),
                "look_mix": np.zeros(n, np.float32) if wc.mix is None else np.asarray(wc.mix, np.float32),
                "look_stroke": np.zeros(n, np.float32) if wc.strokes is None else np.asarray(wc.strokes, np.float32)}  # fmt: skip
    np.savez(
        folder / BLENDER_DATA,
        vertices=np.asarray(mesh.vertices, np.float32),
        faces=np.asarray(mesh.faces, np.int32),
        normals=np.asarray(mesh.normals, np.float32),
        lut=np.asarray(lut.values, np.float32),
        **look,
    )
    written = [folder / BLENDER_SCRIPT, folder / BLENDER_DATA]
    if blend if blend is not None else bpy_available():
        _save_blend(folder)
        written.append(folder / BLENDER_FILE)
    return written


def _save_blend(folder: Path) -> None:
    """Run the script in a fresh Python with `bpy` to save `scene.blend` (Blender holds one scene per process)."""
    cmd = [sys.executable, str(folder / BLENDER_SCRIPT), "--save", str(folder / BLENDER_FILE)]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=_SAVE_TIMEOUT_S, check=False)
    except subprocess.TimeoutExpired:
        raise FailureError(f"building the .blend took over {_SAVE_TIMEOUT_S} s", file=folder / BLENDER_FILE) from None
    if done.returncode != 0 or not (folder / BLENDER_FILE).is_file():
        last = (done.stderr.strip().splitlines() or done.stdout.strip().splitlines() or ["no output"])[-1]
        raise FailureError(f"Blender could not build the scene: {last}", file=folder / BLENDER_FILE)
