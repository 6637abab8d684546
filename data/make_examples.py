"""Regenerate the small inputs the README's and the docs' examples read, in data/examples (run from the
repository root).

    python data/make_examples.py

- `measurements.csv`: a measurement table (docs/fitting.md) of two real paints, the rows of the paper, P1
  (Cadmium Red) and P7 (Sap Green) of `data/ntu-wpsm/ntu-rgb-train.csv` (Chen et al. 2019), renamed.
- `scene.json` and `target.png`: a 96x96 sphere with the scene's default shading constants, and the image
  of the same sphere rendered with the constants and light of `TRUTH` (16-bit sRGB), for `fit-image`
  examples that find them in seconds. `truth.json` records what the target was rendered with.
- `card.jpg` and `card.json`: a synthetic phone photo of a swatch card of the seed's Cerulean Blue and its
  layout (`diffwash.swatchcard`, seed 3), for `fit-swatch` examples.

The outputs are small (a few kB) and deterministic.
"""

import csv
from pathlib import Path

import equinox as eqx
import numpy as np

import diffwash
from diffwash import pigments, swatchcard
from diffwash.io import write_json, write_png

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "data" / "examples"

#: NTU paint codes taken into the example table, and the names they are given there.
PAINTS = {"P1": "Cadmium Red", "P7": "Sap Green"}

SCENE = {
    "mesh": "../meshes/sphere.ply",
    "image": {"width": 96, "height": 96},
    "camera": {"eye": [0.0, 0.0, 3.5], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov_y": 40},
    "light": {"direction": [-1.0, 1.0, 1.0]},
    "shading": "per-pixel",
    "wash": {"pigment": "Cadmium Yellow"},
    "unlit": {"pigment": "Phthalo Green"},
    "k_wash": 1.0, "k_specular": 1.0, "shininess": 12, "k_unlit": 1.0, "gain": 0.5, "bias": 0.5, "wash_reduction": 0.3,
}  # fmt: skip

#: What the target image was rendered with (the scene's other values as above).
TRUTH = {"gain": 0.62, "bias": 0.4, "k_unlit": 1.5, "light": [-0.8, 1.3, 0.9]}


def write_measurements() -> None:
    """The paper row and the rows of `PAINTS` of the NTU table, the paints renamed."""
    with open(ROOT / "data" / "ntu-wpsm" / "ntu-rgb-train.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    keep = [r for r in rows if r["pigment"] == "paper" or r["pigment"] in PAINTS]
    with open(OUT / "measurements.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["pigment", "amount", "ground", "r", "g", "b"], lineterminator="\n")
        w.writeheader()
        for r in keep:
            w.writerow({**r, "pigment": PAINTS.get(r["pigment"], r["pigment"])})


def write_target() -> None:
    """The example scene, and its image rendered with the `TRUTH` constants."""
    write_json(OUT / "scene.json", SCENE)
    scene = diffwash.load_scene(OUT / "scene.json")
    truth = scene.params
    for key, value in TRUTH.items():
        truth = eqx_replace(truth, key, np.asarray(value, dtype=np.float32))
    image = np.asarray(diffwash.render(scene, truth))
    write_png(OUT / "target.png", np.asarray(diffwash.colorimetry.srgb_encode(image)), bits=16)
    write_json(OUT / "truth.json", {**TRUTH, "note": "what target.png was rendered with (data/make_examples.py)"})


def eqx_replace(params: diffwash.Params, field: str, value: np.ndarray) -> diffwash.Params:
    """`params` with one field replaced."""
    return eqx.tree_at(lambda p: getattr(p, field), params, value)


def write_card() -> None:
    """A swatch card of Cerulean Blue, photographed by the default phone camera."""
    card = swatchcard.make_swatch_card(pigments.load("Cerulean Blue"), seed=3)
    swatchcard.save_swatch_card(card, OUT / "card.jpg", OUT / "card.json")


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    write_measurements()
    write_target()
    write_card()
    print(sorted(p.name for p in OUT.iterdir()))


if __name__ == "__main__":
    main()
