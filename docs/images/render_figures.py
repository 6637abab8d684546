"""Regenerate the renderer's figures in docs/images (run from the repository root).

    python docs/images/render_figures.py
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import diffwash  # noqa: E402
from diffwash import colorimetry  # noqa: E402
from diffwash._io import write_png  # noqa: E402

HERE = Path(__file__).parent


def srgb(img) -> np.ndarray:
    return np.asarray(colorimetry.srgb_encode(np.clip(np.asarray(img, np.float64), 0, 1)))


def main() -> None:
    knot = diffwash.load_scene(ROOT / "data" / "scenes" / "knot.json")
    write_png(HERE / "knot.png", srgb(diffwash.render(knot, antialias=True)))

    # Shading modes on a coarse mesh, and antialiasing, side by side.
    coarse = diffwash.load_mesh(ROOT / "data" / "meshes" / "knot-1k.ply")
    small = dataclasses.replace(knot, mesh=coarse, width=256, height=256)
    panels = [
        diffwash.render(small),
        diffwash.render(dataclasses.replace(small, shading="per-vertex")),
    ]
    # A 4x zoom on a silhouette: point-sampled, then antialiased.
    zoom = dataclasses.replace(knot, width=512, height=512)
    crop = (slice(60, 124), slice(300, 364))
    for aa in (False, True):
        img = np.asarray(diffwash.render(zoom, antialias=aa))[crop]
        panels.append(np.repeat(np.repeat(img, 4, axis=0), 4, axis=1))
    gap = np.ones((256, 8, 3))
    row = np.concatenate([x for p in panels for x in (srgb(p), gap)][:-1], axis=1)
    write_png(HERE / "render-modes.png", row)
    print("wrote docs/images/knot.png and docs/images/render-modes.png")


if __name__ == "__main__":
    main()
