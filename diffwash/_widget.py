"""`diffwash.widget(scene)`: the exported WebGL2 shaders, live in a Jupyter cell (anywidget).

The widget draws the scene with the very shaders `diffwash export` writes for
the `webgl2` target (`diffwash._glsl.shader_sources`, both shading modes) and
the LUT `diffwash.lut.bake` bakes, in a canvas of the scene's size, beside a
panel of sliders. Its front end is `diffwash/data/widget/widget.js` (an ES
module in anywidget's form) and `widget.css`.

What a change costs, by what it changes:

- `shininess`, `gain`, `bias`, `wash_reduction`, the light and the shading
  mode are uniforms: the front end redraws, Python does nothing;
- `k_wash`, `k_specular` and `k_unlit` also set the LUT's range
  (`wash_max = k_specular k_wash`, `unlit_max = k_unlit`), and a pigment's K
  and S (or a library mixture's proportions and amount) its values: Python
  re-bakes the table (`lut.bake`, compiled once and reused; `bake_ms` says how
  long it took) and sends it to the front end as half floats, the sRGB-encoded
  values the viewer page embeds.

So the table on screen is always `lut.bake(widget.params, lut_size)`.

A scene with a `"watercolour"` object is drawn with the look's passes, as
`viewer.html` draws them (`diffwash/data/look-runner.js`, one source for
both; the shaders, pass graph and textures of `diffwash._look_export`), with
a slider for each strength, width and amplitude of the effects the scene
turns on (`look`: leaf -> value). Moving one sets its uniform at once; Python
answers with the look's uniforms (`look_uniforms`: the edge blur's weights
follow the width). A pigment, paper or range change re-bakes the look's 3D mix LUT
too (`mix_lut`, half floats). The checkbox shows the plain model instead.
The export button (or `widget.export(folder)`) writes the tuned scene as
`diffwash export` does, the tuned look included.

anywidget and traitlets are optional (the `widget` extra); the rest of
diffwash never imports this module.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import time
from importlib import resources
from pathlib import Path
from typing import Any

import equinox as eqx
import numpy as np

from . import lut as _lut
from ._errors import DiffwashError
from ._export import export as _export
from ._glsl import SHADING_MODES, shader_file_names, shader_sources
from ._lazy import lazy
from ._look_export import look_export
from ._look_glsl import mix_lut as _mix_lut
from ._look_glsl import mix_lut_range
from ._mixture import Mixture
from ._scene import Scene, load_scene
from ._version import __version__
from ._viewer import look_config, look_runner_source
from .colorimetry import to_display
from .look import leaf_specs, look_uniforms
from .pigments import Pigment
from .shading import CONSTANTS, Params, paper_colour

anywidget = lazy("anywidget")
traitlets = lazy("traitlets")

__all__ = ["widget", "RANGE_CONSTANTS", "lut_bytes", "mesh_bytes"]

#: The constants that set the LUT's range: changing one re-bakes the table.
RANGE_CONSTANTS = ("k_wash", "k_specular", "k_unlit")
#: Where the export button writes by default (relative to the kernel's working folder).
DEFAULT_FOLDER = "diffwash-widget-export"


def lut_bytes(table: _lut.Lut) -> bytes:
    """The front end's LUT: the linear values sRGB-encoded (as the PNG LUTs and the viewer hold them), as little-endian half floats, row 0 first."""
    return np.ascontiguousarray(to_display(np.asarray(table.values, np.float64))).astype("<f2").tobytes()


def mesh_bytes(scene: Scene) -> bytes:
    """The mesh as the front end reads it: positions and normals (float32, xyz per vertex), then the faces (uint32)."""
    m = scene.mesh
    parts = [np.asarray(m.vertices, "<f4"), np.asarray(m.normals, "<f4"), np.asarray(m.faces, "<u4")]
    return b"".join(np.ascontiguousarray(p).tobytes() for p in parts)


def _pigment_state(p: Any) -> dict[str, Any]:
    if isinstance(p, Mixture):
        q = np.asarray(p.proportions, np.float64)
        q = q / q.sum() if q.sum() > 0 else q
        return {"mix": {n: float(v) for n, v in zip(p.palette.names, q)}, "amount": float(np.asarray(p.amount))}
    return {"K": np.asarray(p.K, np.float64).tolist(), "S": np.asarray(p.S, np.float64).tolist()}


def _pigment_sliders(p: Any) -> list[dict[str, Any]]:
    """Sliders for one glaze: K and S per channel (log scale), or a mixture's proportions and amount."""
    if isinstance(p, Mixture):
        amount = float(np.asarray(p.amount))
        out = [{"key": f"mix.{n}", "label": n, "min": 0.0, "max": 1.0, "step": 0.01} for n in p.palette.names]
        return out + [{"key": "amount", "label": "amount", "min": amount / 10, "max": amount * 10, "log": True}]
    out = []
    for coef in ("K", "S"):
        values = np.asarray(getattr(p, coef), np.float64)
        for i, channel in enumerate("RGB"):
            top = max(100.0, 10 * float(values[i]))
            out.append({"key": f"{coef}.{i}", "label": f"{coef} {channel}", "min": 1e-3, "max": top, "log": True})
    return out


def _constant_sliders(p: Params) -> list[dict[str, Any]]:
    value = {k: float(np.asarray(getattr(p, k))) for k in CONSTANTS}
    top = {"k_wash": 3.0, "k_specular": 3.0, "k_unlit": 4.0, "shininess": 200.0}
    out = []
    for name in CONSTANTS:
        if name in ("gain", "bias"):
            lo, hi = 0.01, 0.99
        elif name == "wash_reduction":
            lo, hi = 0.0, 1.0
        else:
            lo, hi = 0.0, max(top[name], 2 * value[name])
        step = 10.0 ** np.floor(np.log10((hi - lo) / 500))  # a round step: 0.001 for gain, 0.1 for shininess
        out.append({"key": name, "label": name, "min": lo, "max": hi, "step": float(step), "rebake": name in RANGE_CONSTANTS})
    return out


def _look_leaves(scene: Scene) -> dict[str, float]:
    """The look's leaves a slider moves: the fittable ones of the effects the scene turns on (value > 0)."""
    look = scene.watercolour.look
    return {name: float(np.asarray(getattr(look, name))) for name, spec in leaf_specs().items()
            if spec.fit and float(np.asarray(getattr(look, name))) > 0}  # fmt: skip


def _look_sliders(scene: Scene) -> list[dict[str, Any]]:
    specs = leaf_specs()
    out = []
    for name, value in _look_leaves(scene).items():
        spec = specs[name]
        hi = spec.at_most if spec.at_most is not None else max(4 * value, 4 * spec.on, 1e-3)
        out.append({"key": name, "label": f"{spec.effect}.{spec.key}", "min": 0.0, "max": float(hi), "step": float(hi) / 400,
                    "doc": spec.doc})  # fmt: skip
    return out


def _with_look(scene: Scene, values: dict[str, Any]) -> Scene:
    """`scene` with its look's leaves set to `values` (checked: known leaves, finite, >= 0, within their bound)."""
    if not isinstance(values, dict):
        raise DiffwashError(f"must map leaves to numbers, got {values!r}", field="look")
    if scene.watercolour is None:
        if values:
            raise DiffwashError("the scene has no watercolour look", field="look")
        return scene
    specs, wc, movable = leaf_specs(), scene.watercolour, _look_leaves(scene)
    names = list(values)
    for name in names:
        v = values[name]
        if name not in movable:
            raise DiffwashError(f"is not a slider of this scene's look (choose from {', '.join(movable)})", field=f"look.{name}")
        top = specs[name].at_most
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0 or (top is not None and v > top) or v > 1e6:
            raise DiffwashError(f"must be a number in [0, {top if top is not None else '1e6'}], got {v!r}", field=f"look.{name}")
    if not names:
        return scene
    new = [np.asarray(values[n], np.asarray(getattr(wc.look, n)).dtype) for n in names]
    look = eqx.tree_at(lambda lk: [getattr(lk, n) for n in names], wc.look, new)
    return dataclasses.replace(scene, watercolour=eqx.tree_at(lambda w: w.look, wc, look))


def _look_front(scene: Scene, look: Any) -> dict[str, Any]:
    """What the front end needs once to run the look's passes (`look_config` of the scene's `look_export`), its
    sliders and the layout of its per-vertex attributes (`look_mesh`)."""
    out = look_config(look, np.asarray(scene.mesh.vertices, np.float64))
    n = len(np.asarray(scene.mesh.vertices))
    out["attributes"] = [[name, int(np.asarray(a).size // n)] for name, a in look.attributes.items()]
    out["sliders"] = _look_sliders(scene)
    return out


def _look_mesh(look: Any) -> bytes:
    """The look's per-vertex attributes (`_MIX`, `_STROKE`), float32, one after the other."""
    return b"".join(np.ascontiguousarray(np.asarray(a, "<f4")).tobytes() for a in look.attributes.values())


def _config(scene: Scene, params: Params, lut_size: int, look: Any = None) -> dict[str, Any]:
    """What the front end needs once: the shaders, the camera and size, the mesh's layout, the sliders."""
    shaders = {}
    for mode in SHADING_MODES:
        vert, frag = shader_sources("webgl2", mode, colour="lut", lut_srgb=True, output_srgb=True)
        shaders[mode] = {"vert": vert, "frag": frag, "names": list(shader_file_names(mode))}
    vertices = np.asarray(scene.mesh.vertices, np.float64)
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    cam = scene.camera
    return {
        "title": str(scene.path or "scene"),
        "version": __version__,
        "width": scene.width,
        "height": scene.height,
        "shaders": shaders,
        "vertices": int(vertices.shape[0]),
        "faces": int(np.asarray(scene.mesh.faces).shape[0]),
        "centre": centre.tolist(),
        "radius": float(np.max(np.linalg.norm(vertices - centre, axis=1))),
        "camera": {k: np.asarray(getattr(cam, k), np.float64).tolist() for k in ("eye", "target", "up", "fov_y", "near", "far")},
        "two_sided": not scene.cull_backfaces,
        "lut_size": lut_size,
        "constants": _constant_sliders(params),
        "pigments": {g: {"name": getattr(params, g).name, "sliders": _pigment_sliders(getattr(params, g))} for g in ("wash", "unlit")},
        "paper": _paper_sliders(params),
        "look": None if look is None else _look_front(scene, look),
    }


def _with_pigment(p: Any, state: dict[str, Any], field: str) -> Any:
    """The glaze `p` with the values of its widget state (checked: finite, >= 0, the right shape)."""

    def numbers(value: Any, name: str, shape: tuple[int, ...]) -> np.ndarray:
        try:
            a = np.asarray(value, np.float64) if not isinstance(value, (str, bytes, dict)) else np.asarray(np.nan)
        except (TypeError, ValueError):  # ["a", 1, 2], ragged lists
            a = np.asarray(np.nan)
        if a.shape != shape or not np.all(np.isfinite(a)) or np.any(a < 0) or np.any(a > 1e12):
            raise DiffwashError(f"must be {shape[0] if shape else 'a'} finite number(s) in [0, 1e12], got {value!r}", field=f"{field}.{name}")
        return a

    if isinstance(p, Mixture):
        names = p.palette.names
        mix = state.get("mix", {})
        if not isinstance(mix, dict) or set(mix) != set(names):
            raise DiffwashError(f"must give a proportion for each of {', '.join(names)}", field=f"{field}.mix")
        q = np.array([float(numbers(mix[n], f"mix.{n}", ())) for n in names])
        if q.sum() <= 0:
            raise DiffwashError("the proportions must not all be 0", field=f"{field}.mix")
        amount = float(numbers(state.get("amount", p.amount), "amount", ()))
        if amount <= 0:
            raise DiffwashError(f"must be > 0, got {amount}", field=f"{field}.amount")
        return dataclasses.replace(p, proportions=q, amount=np.float64(amount))
    size = np.asarray(p.K).shape
    return dataclasses.replace(p, K=numbers(state.get("K"), "K", size), S=numbers(state.get("S"), "S", size))


def _paper_sliders(p: Params) -> list[dict[str, Any]] | None:
    """Sliders for the paper's reflectance per channel (None for spectral glazes, whose paper is per band)."""
    if p.observation is not None or np.asarray(p.paper).shape != (3,):
        return None
    return [{"key": f"paper.{i}", "label": f"paper {c}", "min": 0.0, "max": 1.0, "step": 0.001} for i, c in enumerate("RGB")]


def _params(base: Params, wash: dict, unlit: dict, constants: dict, light: list, paper: list | None = None) -> Params:
    """`base` with the widget's values (float64 NumPy scalars, as loaded scenes hold: the compiled bake is reused)."""
    c = {}
    for name in CONSTANTS:
        v = constants.get(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0 or v > 3.4e38:
            raise DiffwashError(f"must be a finite number >= 0, got {v!r}", field=f"constants.{name}")
        c[name] = np.float64(v)
    direction = np.asarray(light, np.float64)
    if direction.shape != (3,) or not np.all(np.isfinite(direction)) or not np.any(direction):
        raise DiffwashError(f"must be 3 finite numbers, not all 0, got {light!r}", field="light")
    if paper:  # an RGB scene's paper (a spectral one has no paper slider: [])
        numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in paper)
        reflectance = np.asarray(paper, np.float64) if numbers else None
        if _paper_sliders(base) is None or reflectance is None or reflectance.shape != (3,) or not np.all((reflectance >= 0) & (reflectance <= 1)):
            raise DiffwashError(f"must be 3 reflectances in [0, 1] (an RGB scene's paper), got {paper!r}", field="paper")
        c["paper"] = reflectance
    return dataclasses.replace(
        base, wash=_with_pigment(base.wash, wash, "wash"), unlit=_with_pigment(base.unlit, unlit, "unlit"), light=direction, **c
    )


def _front_end(name: str) -> str:
    return (resources.files("diffwash") / "data" / "widget" / name).read_text(encoding="utf-8")


class _Widget:
    """The widget's behaviour; `_widget_class` puts it on an `anywidget.AnyWidget` with the synced traits."""

    def __init__(self, scene: Scene, params: Params, lut_size: int, **kwargs: Any) -> None:
        self._scene, self._base, self._lut_size = scene, params, lut_size
        self._table: _lut.Lut | None = None
        self._ready = False
        look = None if scene.watercolour is None else look_export(scene, params)
        super().__init__(  # type: ignore[call-arg]
            config=_config(scene, params, lut_size, look),
            mesh=mesh_bytes(scene),
            shading=scene.shading,
            constants={k: float(np.asarray(getattr(params, k))) for k in CONSTANTS},
            light=np.asarray(params.light, np.float64).tolist(),
            wash=_pigment_state(params.wash),
            unlit=_pigment_state(params.unlit),
            look=_look_leaves(scene) if scene.watercolour is not None else {},
            paper=np.asarray(params.paper, np.float64).tolist() if _paper_sliders(params) else [],
            background=to_display(np.asarray(paper_colour(params), np.float64)).tolist(),
            look_mesh=b"" if look is None else _look_mesh(look),
            **kwargs,
        )
        self._ready = True
        self.rebake()
        self.on_msg(self._on_message)

    @property
    def params(self) -> Params:
        """The tuned shading `Params`."""
        return _params(self._base, self.wash, self.unlit, self.constants, self.light, self.paper)

    @property
    def scene(self) -> Scene:
        """The scene with the tuned `params`, shading mode and look."""
        scene = dataclasses.replace(self._scene, params=self.params, shading=self.shading)
        return scene if scene.watercolour is None else _with_look(scene, self.look)

    @property
    def table(self) -> _lut.Lut | None:
        """The `Lut` on screen: `lut.bake(self.params, lut_size)`."""
        return self._table

    def rebake(self) -> _lut.Lut:
        """Bake the LUT for the current values and send it to the front end; `bake_ms` is the time it took."""
        start = time.perf_counter()
        params = self.params
        table = _lut.bake(params, self._lut_size)
        data = lut_bytes(table)
        look = None if self._scene.watercolour is None else _mix_lut(self._scene, params)[0]  # the look's 3D mix LUT
        elapsed = 1000 * (time.perf_counter() - start)
        self._table = table
        with self.hold_sync():
            self.lut_range = [float(table.wash_max), float(table.unlit_max)]
            self.lut = data
            self.background = to_display(np.asarray(paper_colour(params), np.float64)).tolist()
            if look is not None:
                self.mix_lut = look.astype("<f2").tobytes()
                self._send_look_uniforms()
            self.bake_ms = elapsed
        return table

    def _send_look_uniforms(self) -> None:
        """The look's uniforms for the current leaves (`look.look_uniforms`: the edge blur's weights follow its width)
        and the mix LUT's range (`mix_lut_range`)."""
        scene = _with_look(self._scene, self.look)
        wc = scene.watercolour
        u = look_uniforms(wc.look, wc.pigments, height=scene.height)
        u["lut_wash_max"], u["lut_unlit_max"] = mix_lut_range(self.params)
        self.look_uniforms = {k: [float(x) for x in v] if isinstance(v, (list, tuple)) else v for k, v in u.items()}

    def export(self, folder: str | os.PathLike | None = None, *, overwrite: bool = True) -> list[Path]:
        """Write the tuned scene as `diffwash export` does (into `folder`, default `export_folder`); a previous export there is replaced."""
        folder = Path(self.export_folder if folder is None else folder)
        written = _export(self.scene, folder, overwrite=overwrite, size=self._lut_size)
        self.status = f"exported {len(written)} files to {folder}"
        return written

    def _check_values(self, proposal: Any) -> Any:
        """A value the model cannot take is refused before it is set (`DiffwashError` naming the field)."""
        if self._ready:
            values = {k: getattr(self, k) for k in ("wash", "unlit", "constants", "light", "paper")}
            values[proposal["trait"].name] = proposal["value"]
            _params(self._base, **values)
        return proposal["value"]

    def _check_look(self, proposal: Any) -> Any:
        if self._ready:
            _with_look(self._scene, proposal["value"])
        return proposal["value"]

    def _on_look_leaf(self, change: dict) -> None:
        """A look slider: its uniform is set in the page already; the uniforms that derive from it come back."""
        if self._ready:
            self._send_look_uniforms()

    def _check_shading(self, proposal: Any) -> Any:
        if proposal["value"] not in SHADING_MODES:
            raise DiffwashError(f"must be one of {', '.join(SHADING_MODES)}, got {proposal['value']!r}", field="shading")
        return proposal["value"]

    def _changed(self, change: dict) -> None:
        """Re-bake for a pigment, or for a constant that sets the table's range; the other constants are uniforms."""
        if not self._ready:
            return
        if change["name"] == "constants" and all(change["old"].get(k) == change["new"].get(k) for k in RANGE_CONSTANTS):
            return
        self.rebake()

    def _on_message(self, _widget: Any, content: Any, _buffers: Any) -> None:
        if isinstance(content, dict) and content.get("type") == "export":
            try:
                self.export()
            except (DiffwashError, OSError) as e:
                self.status = f"error: {e}"


@functools.cache
def _widget_class() -> type:
    """The anywidget class, made on first use (anywidget and traitlets are optional)."""
    t = traitlets

    class DiffwashWidget(_Widget, anywidget.AnyWidget):
        """A scene drawn live with the exported WebGL2 shaders (`diffwash.widget`)."""

        _esm = t.Unicode(look_runner_source() + "\n" + _front_end("widget.js")).tag(sync=True)
        _css = t.Unicode(_front_end("widget.css")).tag(sync=True)
        config = t.Dict().tag(sync=True)
        mesh = t.Bytes().tag(sync=True)
        shading = t.Unicode("per-pixel").tag(sync=True)
        constants = t.Dict().tag(sync=True)
        light = t.List(t.Float()).tag(sync=True)
        wash = t.Dict().tag(sync=True)
        unlit = t.Dict().tag(sync=True)
        lut = t.Bytes().tag(sync=True)
        lut_range = t.List(t.Float()).tag(sync=True)
        bake_ms = t.Float(0.0).tag(sync=True)
        export_folder = t.Unicode(DEFAULT_FOLDER).tag(sync=True)
        status = t.Unicode("").tag(sync=True)
        look = t.Dict().tag(sync=True)
        paper = t.List(t.Float()).tag(sync=True)
        background = t.List(t.Float()).tag(sync=True)
        look_uniforms = t.Dict().tag(sync=True)
        look_mesh = t.Bytes(b"").tag(sync=True)
        mix_lut = t.Bytes(b"").tag(sync=True)

        _validate_values = t.validate("wash", "unlit", "constants", "light", "paper")(_Widget._check_values)
        _validate_shading = t.validate("shading")(_Widget._check_shading)
        _validate_look = t.validate("look")(_Widget._check_look)
        _observe_look = t.observe("look")(_Widget._on_look_leaf)
        _observe = t.observe("wash", "unlit", "constants", "paper")(_Widget._changed)

    return DiffwashWidget


def widget(scene: Scene | str | os.PathLike, *, params: Params | None = None, lut_size: int = 256) -> Any:
    """A Jupyter widget drawing `scene` live with the exported WebGL2 shaders, with sliders for its constants and pigments.

    **Arguments:**

    - `scene`: a `Scene` or the path of a scene file.
    - `params`: shading `Params` to start from (default: the scene's).
    - `lut_size`: the LUT's samples per axis (default 256, as `diffwash export`).

    **Returns:**

    An `anywidget.AnyWidget`: display it (the last line of a cell). Its traits
    `constants`, `light`, `shading`, `wash` and `unlit` follow the sliders
    both ways; `params` and `scene` are the tuned values, `table` the LUT on
    screen, `export(folder)` writes the tuned scene (the panel's button does
    it into `export_folder`).
    """
    if isinstance(scene, (str, os.PathLike)):
        scene = load_scene(scene)
    if not isinstance(scene, Scene):
        raise TypeError(f"widget() takes a Scene or a scene file path, got {type(scene).__name__}")
    _lut.check_size(lut_size, "lut_size")
    return _widget_class()(scene, scene.params if params is None else params, int(lut_size))
