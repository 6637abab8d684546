"""Swatch charts: pigments glazed at several coats over white paper and over black.

The classic figure of Curtis et al. (1997, fig. 4): each pigment's colour
depends on what lies under it, and the two grounds show its absorption (over
white) and its scattering (over black) at a glance.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from . import colorimetry, km
from ._io import save_figure
from ._lazy import lazy
from .pigments import Pigment
from .shading import DEFAULT_PAPER

mpl_figure = lazy("matplotlib.figure")

__all__ = ["DEFAULT_COATS", "swatch_colours", "draw_chart", "save_chart"]

#: Coats (thicknesses, in units of the pigment's K and S) the chart shows.
DEFAULT_COATS = (0.25, 0.5, 1.0, 2.0, 4.0)


def swatch_colours(
    pigment: Pigment, coats: Sequence[float] = DEFAULT_COATS, paper: Sequence[float] = DEFAULT_PAPER
) -> tuple[np.ndarray, np.ndarray]:
    """Display sRGB colours of `pigment` at each coat over `paper` and over black.

    **Returns:**

    `(over_paper, over_black)`, each (len(coats), 3) in [0, 1].
    """
    x = jnp.asarray(coats, float)[:, None]
    R, T = km.layer(pigment.K, pigment.S, x)
    on_paper = km.over(R, T, jnp.asarray(paper, float))
    on_black = R
    return colorimetry.to_display(on_paper), colorimetry.to_display(on_black)


def draw_chart(
    pigments: Sequence[Pigment], coats: Sequence[float] = DEFAULT_COATS, paper: Sequence[float] = DEFAULT_PAPER
):
    """A labelled matplotlib figure: one row per pigment, one column per coat.

    Each swatch is painted across a white (paper) stripe and a black stripe:
    the top of the swatch lies over paper, the bottom over black, with the bare
    grounds on either side.
    """
    paper_srgb = colorimetry.to_display(paper)
    n, m = len(pigments), len(coats)
    cell, pad = 40, 8  # pixels of a half swatch, gap
    width = m * (cell + pad) + pad
    height = n * (2 * cell + 2 * pad)
    img = np.ones((height, width, 3))
    for i, pig in enumerate(pigments):
        over_paper, over_black = swatch_colours(pig, coats, paper)
        y0 = i * (2 * cell + 2 * pad) + pad // 2
        img[y0 : y0 + cell + pad // 2, :] = paper_srgb  # paper stripe
        img[y0 + cell + pad // 2 : y0 + 2 * cell + pad, :] = 0.0  # black stripe
        for j in range(m):
            x0 = pad + j * (cell + pad)
            img[y0 + pad // 2 : y0 + cell + pad // 2, x0 : x0 + cell] = over_paper[j]
            img[y0 + cell + pad // 2 : y0 + 2 * cell + pad // 2, x0 : x0 + cell] = over_black[j]
    dpi = 100
    label_w = 170
    fig = mpl_figure.Figure(figsize=((width + label_w) / dpi, (height + 56) / dpi), dpi=dpi)  # not pyplot: no backend
    ax = fig.add_axes([label_w / (width + label_w), 0, width / (width + label_w), height / (height + 56)])
    ax.imshow(img, interpolation="nearest", aspect="equal")
    ax.set_xticks([pad + j * (cell + pad) + cell / 2 for j in range(m)])
    ax.set_xticklabels([f"{c:g}" for c in coats], fontsize=8)
    ax.xaxis.set_ticks_position("top")
    ax.set_xlabel("coats (top: over paper, bottom: over black)", fontsize=8)
    ax.xaxis.set_label_position("top")
    ax.set_yticks([i * (2 * cell + 2 * pad) + cell + pad // 2 for i in range(n)])
    ax.set_yticklabels([p.name for p in pigments], fontsize=9)
    ax.tick_params(length=0)
    for s in ax.spines.values():
        s.set_visible(False)
    return fig


def save_chart(
    path: str | os.PathLike,
    pigments: Sequence[Pigment],
    coats: Sequence[float] = DEFAULT_COATS,
    paper: Sequence[float] = DEFAULT_PAPER,
) -> None:
    """Draw the swatch chart and write it as the PNG or JPEG its extension names, atomically."""
    save_figure(path, draw_chart(pigments, coats, paper), facecolor="white")
