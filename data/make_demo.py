"""Regenerate the demo's bundled data in diffwash/data/demo (run from the repository root).

    python data/make_demo.py

The demo pretends to be a technical artist's first session: a phone photo of a swatch card of a
pigment that is not in the library, a mesh, and a target image painted (rendered) with shading
constants the demo must find. This script makes all three with the project's own generators and
records the truth in truth.json, so the demo and its test can say how close the fits come.
"""

import json
import shutil
from pathlib import Path

import numpy as np

import diffwash
from diffwash import swatchcard
from diffwash._io import write_json, write_png
from diffwash.pigments import Pigment

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "diffwash" / "data" / "demo"

#: The mystery pigment on the card: a warm, transparent gold (not one of the seed's 12).
PIGMENT = Pigment(K=np.array([0.12, 0.55, 2.4]), S=np.array([0.35, 0.25, 0.05]), name="Quinacridone Gold")
#: The shading constants the target image was painted with.
TRUE_CONSTANTS = {"gain": 0.62, "bias": 0.38, "k_wash": 1.3, "k_unlit": 1.6, "shininess": 28.0, "wash_reduction": 0.35}

SCENE = {
    "mesh": "knot.ply",
    "image": {"width": 256, "height": 256},
    "camera": {"eye": [0.0, 0.4, 3.2], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov_y": 40},
    "light": {"direction": [1.0, 1.2, 0.8]},
    "shading": "per-pixel",
    "paper": [0.92, 0.90, 0.84],
    "wash": {"pigment": "Cadmium Yellow"},  # a stand-in: the demo puts the card's fitted pigment here
    "unlit": {"pigment": "French Ultramarine"},
    "k_wash": 1.0, "k_specular": 1.0, "shininess": 20, "k_unlit": 1.0, "gain": 0.5, "bias": 0.5, "wash_reduction": 0.0,
}  # fmt: skip


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    card = swatchcard.make_swatch_card(PIGMENT, coats=(1, 2, 3, 4), seed=7)
    swatchcard.save_swatch_card(card, OUT / "card.jpg", OUT / "card.json")

    shutil.copyfile(ROOT / "data" / "meshes" / "knot-10k.ply", OUT / "knot.ply")
    write_json(OUT / "scene.json", SCENE)

    scene = diffwash.load_scene(OUT / "scene.json")
    truth = diffwash.Params(**{**{f: getattr(scene.params, f) for f in ("paper", "light", "k_specular", "unlit")},
                               "wash": PIGMENT, **TRUE_CONSTANTS})  # fmt: skip
    target = np.asarray(diffwash.render(scene, truth))
    write_png(OUT / "target.png", np.asarray(diffwash.colorimetry.srgb_encode(target)), bits=16)
    write_json(OUT / "truth.json", {"pigment": PIGMENT.to_dict(), "constants": TRUE_CONSTANTS,
                                    "note": "what card.jpg and target.png were made with (data/make_demo.py)"})  # fmt: skip
    print(json.dumps(sorted(p.name for p in OUT.iterdir())))


if __name__ == "__main__":
    main()
