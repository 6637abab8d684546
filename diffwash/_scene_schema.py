"""The scene file's format, declared once (pydantic v2, as `diffwash._schema`): keys, types, ranges, defaults, meanings.

`parse_scene` checks a scene's JSON against `SceneFile` before it loads anything, and keeps only what a schema
cannot say (the mesh, the camera's geometry, library look-ups, glazes seen alike). The `"watercolour"` object's
effects are built from the look's own declaration (`diffwash.look.leaf_specs`: each leaf's key, default, bound
and meaning) plus each effect's other keys (`_OPTIONS`), so adding a look effect touches its declaration only.
docs/scene-format.md embeds `format_table` of each model (a test holds them equal).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import pydantic
from pydantic import AfterValidator, BaseModel, Discriminator, Field, Tag

from . import look as wl
from ._schema import Direction, Flag, Name, Number, Shaped, Text, Vec3, Whole, _Located, _Part, name_key
from .shading import DEFAULT_CONSTANTS, SHADING_MODES

__all__ = ["SceneFile", "WatercolourObject", "EFFECTS", "ON_BY_DEFAULT", "MAX_IMAGE_SIDE", "BACKFACE_MODES"]

#: Largest image side the renderer accepts (pixels).
MAX_IMAGE_SIDE = 8192
BACKFACE_MODES = ("auto", "cull", "both")

NonNegative = Annotated[Number, Field(ge=0)]
Positive = Annotated[Number, Field(gt=0)]
Seed = Annotated[Whole, Field(ge=0, lt=2**32)]


def _triple(item: Any, message: str) -> Any:
    return Annotated[list[item], Field(min_length=3, max_length=3), Shaped(message)]


class Image(_Part):
    """The image's size (`--size WxH` overrides it)."""

    width: Annotated[Whole, Field(ge=1, le=MAX_IMAGE_SIDE)] = Field(512, description="pixels")
    height: Annotated[Whole, Field(ge=1, le=MAX_IMAGE_SIDE)] = Field(512, description="pixels")


class Camera(_Part):
    """A pinhole camera looking from `eye` at `target`."""

    eye: Vec3 = Field(description="camera position, world space")
    target: Vec3 = Field(description="the point looked at; must differ from `eye`")
    up: Vec3 = Field([0.0, 1.0, 0.0], description="up direction; must not be parallel to `target - eye`")
    fov_y: Annotated[Number, Field(gt=0, lt=180)] = Field(40.0, description="vertical field of view in degrees")
    near: Positive | None = Field(None, description="near clip distance along the view axis; by default 1% before "
                                  "the mesh's bounding sphere (at least `far / 1000`)")  # fmt: skip
    far: Number | None = Field(None, description="far clip distance, > `near`; by default 1% beyond the mesh's "
                               "bounding sphere")  # fmt: skip


class Light(_Part):
    """The light."""

    direction: Direction = Field(description="direction *towards* the light, world space, any non-zero length")


class PigmentRef(_Part):
    """A glaze of a three-channel pigment by name or file."""

    pigment: Name = Field(description="a name from the pigment library (matched ignoring case), or a pigment file "
                          "relative to the scene")  # fmt: skip
    name: Text | None = Field(None, description="the pigment of a library file")


class InlinePigment(_Part):
    """A glaze of a three-channel pigment written out."""

    K: _triple(NonNegative, "must be a list of 3 finite numbers") = Field(description="absorption per channel")  # type: ignore[valid-type]
    S: _triple(NonNegative, "must be a list of 3 finite numbers") = Field(description="scattering per channel")  # type: ignore[valid-type]
    name: Text | None = Field(None, description="the pigment's name")
    density: NonNegative | None = Field(None, description="as in a pigment file")
    staining: NonNegative | None = Field(None, description="as in a pigment file")
    granularity: NonNegative | None = Field(None, description="as in a pigment file")


def _distinct(mix: dict[str, float]) -> dict[str, float]:
    seen: dict[str, str] = {}
    for name in mix:
        first = seen.setdefault(name_key(name), name)
        if first != name:
            raise _Located(f"names the pigment of {first!r} again (names are compared ignoring case and spaces)", (name,))
    return mix


#: A paint's pigments and their proportions.
Mix = Annotated[dict[Name, NonNegative], Field(min_length=1), AfterValidator(_distinct)]


class LibraryGlaze(_Part):
    """A glaze of a fitted library's paint: one pigment, or several mixed in one layer."""

    library: Name = Field(description="the library file (written by `fit-swatch --table`), relative to the scene")
    pigment: Name | None = Field(None, description="one pigment of the library, by name (matched ignoring case)")
    mix: Mix | None = Field(None, description="`{NAME: proportion, ...}`: the paint's pigments and their shares, "
                            "summing to 1")  # fmt: skip
    amount: Positive | None = Field(None, description="the amount of paint in a glaze of thickness 1 (the library's "
                                    "unit); by default the library's reference amount")  # fmt: skip

    @pydantic.model_validator(mode="after")
    def _one_paint(self) -> "LibraryGlaze":
        if (self.pigment is None) == (self.mix is None):
            raise _Located('needs either "pigment" (a name in the library) or "mix" ({"NAME": proportion, ...})', ())
        return self


def _glaze_kind(v: Any) -> str | None:
    if isinstance(v, str):
        return "name"
    if isinstance(v, dict):
        return "library" if "library" in v else "pigment" if "pigment" in v else "K" if "K" in v or "S" in v else None
    return None


#: A glaze's paint: a pigment name, `{"pigment": ...}`, `{"K": ..., "S": ...}` or `{"library": ..., ...}`.
Glaze = Annotated[
    Annotated[Name, Tag("name")] | Annotated[PigmentRef, Tag("pigment")] | Annotated[InlinePigment, Tag("K")]
    | Annotated[LibraryGlaze, Tag("library")],
    Discriminator(_glaze_kind), Shaped('must be {"pigment": NAME_OR_FILE}, {"K": [...], "S": [...]} or '
                                       '{"library": FILE, "pigment": NAME} (or "mix")', union=True),
]  # fmt: skip


class PaperGround(_Part):
    """A paper that is a measured ground of a pigment library."""

    ground: Name = Field(description="the ground's name in the library")
    library: Name | None = Field(None, description="the library file; by default the glazes' library")


#: The paper: reflectances (3, or one per band of spectral glazes) or a library's ground.
Paper = Annotated[
    Annotated[list[NonNegative], Field(min_length=1)] | PaperGround,
    Shaped('must be a list of reflectances >= 0 or {"ground": NAME}', union=True),
]

#: The shading constants' ranges (default: >= 0) and meanings; their defaults are the model's (`DEFAULT_CONSTANTS`).
_CONSTANTS: dict[str, tuple[dict, str]] = {
    "k_wash": ({}, "wash thickness scale"),
    "k_specular": ({}, "wash thickness scale of the specular term"),
    "shininess": ({}, "exponent `n` of the highlight that the wash leaves bare"),
    "k_unlit": ({}, "unlit thickness scale"),
    "gain": ({"gt": 0, "lt": 1}, "Perlin's gain on the unlit fraction; 0.5 is the identity"),
    "bias": ({"gt": 0, "lt": 1}, "Schlick's bias on the unlit fraction; 0.5 is the identity"),
    "wash_reduction": ({"ge": 0, "le": 1}, "how much the wash thins where the unlit glaze lies"),
}


# --- the "watercolour" object ---------------------------------------------------------------------------------------


class MixAxis(_Part):
    """A mix map as a smooth ramp across the mesh along an axis."""

    axis: Direction = Field(description="the ramp's direction, object space")
    softness: Annotated[Number, Field(gt=0, le=10)] = Field(0.25, description="the ramp's width, in object sizes")


#: A mix per vertex: a list, a .npy file (relative to the scene) or `{"axis": ..., "softness": ...}`.
MixMap = Annotated[list[Number] | Name | MixAxis,
                   Shaped("must be a list (one number per vertex), a .npy file or {\"axis\": [x, y, z]}", union=True)]

#: Each effect's keys that are not `Look` leaves (files, seeds, choices, sizes), in the documented order. The leaves'
#: keys, defaults, bounds and meanings are declared once, on `Look` (`look.leaf_specs`): an effect with leaves only
#: needs no entry here.
_OPTIONS: dict[str, dict[str, tuple[Any, Any]]] = {
    "paper": {
        "image": (Name | None, Field(None, description="a greyscale height image (white = peaks), relative to the "
                                     "scene, 8x8 to 2048x2048, tiled in screen space; by default procedural")),
        "seed": (Seed, Field(0, description="seed of the procedural paper and of the unevenness noises")),
        "relief": (NonNegative, Field(2.0, description="the paper's depth for its relief shading")),
    },
    "edges": {},
    "unevenness": {},
    "strokes": {
        "direction": (Literal["min", "max"], Field("max", description="`max`: strokes across the shape (principal "
                                                   "direction of largest curvature), `min`: along it")),
        "length": (Positive, Field(0.25, description="stroke length in object units (at most 10 mesh sizes)")),
        "seed": (Seed, Field(0, description="the stroke noise's seed")),
    },
    "shadow": {},
    "hatching": {"scale": (Positive, Field(190.0, description="hatch texels per object unit"))},
    "mix": {
        "wash": (Glaze | None, Field(None, description="the wash pigment at mix 1 (as `wash`); by default the "
                                     "scene's")),
        "unlit": (Glaze | None, Field(None, description="the unlit pigment at mix 1; by default the scene's")),
        "map": (MixMap, Field(description="the mix per vertex in [0, 1]: a list, a `.npy` file or "
                              "`{\"axis\": [x, y, z], \"softness\": 0.25}` (below)")),
    },
}
#: The effects, in the documented order: those with options, then any with leaves only.
EFFECTS: tuple[str, ...] = tuple(dict.fromkeys([*_OPTIONS, *(s.effect for s in wl.leaf_specs().values())]))
#: Effects on unless the scene says otherwise: those whose leaves are on in `Look`'s defaults (hatching and the mix
#: are asked for).
ON_BY_DEFAULT = tuple(dict.fromkeys(s.effect for s in wl.leaf_specs().values() if s.fit and s.default != 0))


def _effect_model(effect: str) -> type[BaseModel]:
    fields = dict(_OPTIONS.get(effect, {}))
    for spec in wl.leaf_specs().values():
        if spec.effect == effect:
            fields[spec.key] = (Annotated[Number, Field(ge=0, le=spec.at_most)], Field(spec.on, description=spec.doc))
    name = "Watercolour" + effect.title()
    return pydantic.create_model(name, __base__=_Part, __doc__=f"The watercolour look's `{effect}` effect.", **fields)


#: Each effect's object model (`WatercolourPaper`, ...).
EFFECT_MODELS: dict[str, type[BaseModel]] = {effect: _effect_model(effect) for effect in EFFECTS}


def _effect_field(effect: str) -> tuple[Any, Any]:
    model = EFFECT_MODELS[effect]
    on = effect in ON_BY_DEFAULT
    # `true` is the effect's defaults: read as `{}`, so an effect with a required key (mix's map) says it is missing
    return (Annotated[model | Flag, Shaped("must be a JSON object or false", union=True),
                      pydantic.BeforeValidator(lambda v: {} if v is True else v)],
            Field(model() if on else False, description=f"{'on' if on else 'off'} unless set; `false` is off, "
                  f"`true` or `{{}}` its defaults ({model.__name__})"))  # fmt: skip


WatercolourObject = pydantic.create_model(
    "WatercolourObject", __base__=_Part, __doc__="The scene's `\"watercolour\"` object: one key per effect.",
    **{effect: _effect_field(effect) for effect in EFFECTS},
)  # fmt: skip


class _SceneKeys(_Part):
    """A scene file (`diffwash render`, `diffwash.load_scene`)."""

    mesh: Name = Field(description="a triangle mesh, relative to the scene file; any format trimesh reads (PLY, OBJ, "
                               "STL, GLB/glTF, OFF, ...); a file of several meshes is joined into one")
    image: Image = Field(default_factory=Image, description="`{width, height}` (below)")
    camera: Camera = Field(description="`{eye, target, up, fov_y, near, far}` (below)")
    light: Light = Field(description="`{direction}` (below)")
    shading: Literal[SHADING_MODES] = Field("per-pixel", description="where the thicknesses are computed: per pixel "  # type: ignore[valid-type]
                                            "or per vertex")  # fmt: skip
    backfaces: Literal[BACKFACE_MODES] = Field("auto", description="`cull` hides triangles facing away, `both` "  # type: ignore[valid-type]
                                               "draws them, `auto` culls for closed meshes only")  # fmt: skip
    paper: Paper | None = Field(None, description="linear reflectance of the paper: 3 in [0, 1] (default "  # type: ignore[valid-type]
                                "0.92, 0.90, 0.84), one per band for spectral glazes, or a library's ground "
                                "`{\"ground\": NAME, \"library\": FILE}` (default with spectral glazes: `paper`)")
    wash: Glaze = Field(description="the wash glaze's paint: `\"NAME\"`, `{\"pigment\": NAME_OR_FILE}`, "  # type: ignore[valid-type]
                        "`{\"K\": [r, g, b], \"S\": [r, g, b]}` or a library's `{\"library\": FILE, \"pigment\": "
                        "NAME}` / `\"mix\"` (below)")
    unlit: Glaze = Field(description="the unlit glaze's paint, as `wash`")  # type: ignore[valid-type]
    meta: Any = Field(None, description="anything; kept when diffwash writes the scene back")
    watercolour: Annotated[WatercolourObject | Literal[False] | None,  # type: ignore[valid-type]
                           Shaped("must be a JSON object or false", union=True)] = Field(
        None, description="the watercolour look (below); absent or `false`: the plain model")


SceneFile = pydantic.create_model(
    "SceneFile", __base__=_SceneKeys, __doc__=_SceneKeys.__doc__,
    **{k: (Annotated[Number, Field(**(_CONSTANTS[k][0] or {"ge": 0}))], Field(v, description=_CONSTANTS[k][1]))
       for k, v in DEFAULT_CONSTANTS.items()},
)  # fmt: skip
