"""Report pictures of fits: observed and fitted colours side by side, with their errors.

Each patch is drawn as a square whose left half is the colour observed and
whose right half the colour the fitted pigment predicts, captioned with what
it is and the CIEDE2000 between the two. A swatch report also shows the photo
with the layout's boxes drawn over it, and the fitted pigment at more coats
than the card has.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from .. import colorimetry
from .._io import atomic_path, read_image
from .._render import render

__all__ = ["save_swatch_report", "save_table_report", "save_mixture_report", "save_image_report"]


def _display(linear: Any) -> np.ndarray:
    return colorimetry.to_display(linear)


def _figure(**kwargs: Any) -> Any:
    """A matplotlib `Figure` outside pyplot: no backend is chosen or switched (the caller's, e.g. a
    notebook's inline plotting, stays as it is) and nothing is left open."""
    return Figure(**kwargs)


def _pairs(
    ax, groups: Sequence[tuple[str, Sequence[tuple[str, Any, Any, float]]]], title: str, step: float = 1.6
) -> None:
    """Draw rows of observed|fitted squares: groups = [(row label, [(caption, obs, fit, dE), ...])]."""
    n_cols = max(len(items) for _, items in groups)
    for r, (label, items) in enumerate(groups):
        y = -r * step
        ax.text(-0.15, y + 0.5, label, ha="right", va="center", fontsize=8)
        for c, (caption, obs, fit, de) in enumerate(items):
            x = c * 1.25
            ax.add_patch(Rectangle((x, y), 0.5, 1, color=_display(obs)))
            ax.add_patch(Rectangle((x + 0.5, y), 0.5, 1, color=_display(fit)))
            ax.add_patch(Rectangle((x, y), 1, 1, fill=False, lw=0.5, color="0.5"))
            colour = "black" if de <= 1 else ("darkorange" if de <= 2 else "red")
            ax.text(x + 0.5, y - 0.08, f"{caption}\nΔE {de:.2f}", ha="center", va="top", fontsize=6.5, color=colour)
    ax.set_xlim(-0.1, n_cols * 1.25)
    ax.set_ylim(-(len(groups) - 1) * step - step + 0.9, 1.1)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(title, fontsize=9, loc="left")


def _floor_mark(patch: Any) -> str:
    """' (b: floor)' for a patch whose blue channel is at the camera's noise floor, etc."""
    floor = getattr(patch, "floor", None) or []
    marked = "".join(c for c, f in zip("rgb", floor) if f)
    return f" ({marked}: floor)" if marked else ""


def _save(fig, path: str | os.PathLike) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, facecolor="white")


def save_swatch_report(path: str | os.PathLike, fit: Any, photo: np.ndarray | None = None, layout: Any = None) -> None:
    """Write a PNG report of a `SwatchFit`: the photo with its boxes, patches observed vs fitted, and more coats.

    **Arguments:**

    - `path`: the PNG to write (atomically).
    - `fit`: the `SwatchFit`.
    - `photo`: the (first) photo as displayed, (H, W, 3) in [0, 1], to show with its boxes.
    - `layout`: that photo's `Layout`.
    """
    groups = []
    for ground in ("paper", "black"):
        items = [p for p in fit.patches if p.ground == ground]
        if items:
            items.sort(key=lambda p: p.coats)
            groups.append((f"over {ground}", [(f"{p.coats:g} coat{'s' if p.coats != 1 else ''}" + _floor_mark(p),
                                               p.observed, p.fitted, p.delta_e) for p in items]))  # fmt: skip
    coats = np.array([0.25, 0.5, 1, 2, 4, 8])
    more = []
    for ground in ("paper", "black"):
        if ground == "black" and fit.black is None:
            continue
        pred = fit.predict(coats, ground)
        more.append((ground, pred))
    n_cols = max(len(items) for _, items in groups)
    lines = fit.interval_lines() if hasattr(fit, "interval_lines") else []
    extra = 0.16 * len(lines)
    fig = _figure(figsize=(3.2 + 1.0 * max(n_cols, 6), (6.2 if photo is not None else 4.2) + extra))
    k = fit.pigment
    status = (f"converged in {fit.iterations} steps" if fit.converged
              else f"DID NOT CONVERGE in {fit.iterations} steps: do not use these values")  # fmt: skip
    fig.suptitle(f"{k.name}: K = {np.round(k.K, 3).tolist()}, S = {np.round(k.S, 3).tolist()} per coat\n"
                 f"mean CIEDE2000 {fit.mean_delta_e:.2f} over {len(fit.patches)} patches, {status}",
                 fontsize=9, x=0.02, ha="left", color="black" if fit.converged else "red")  # fmt: skip
    for i, line in enumerate(lines):  # intervals, and the bounds where the photo does not determine a value
        flagged = " < " in line or " > " in line or "not determined" in line
        fig.text(0.02, 1 - (0.085 + 0.022 * i) * 6.2 / fig.get_figheight(), line, fontsize=6.5, ha="left",
                 va="top", color="darkorange" if flagged else "0.2")  # fmt: skip
    top = 1 - extra / fig.get_figheight()  # room for the interval lines
    if photo is not None:
        ax = fig.add_axes([0.02, 0.5 * top, 0.45, 0.38 * top])
        ax.imshow(np.clip(photo, 0, 1))
        if layout is not None:
            b = layout.paper
            ax.add_patch(Rectangle((b.x0, b.y0), b.width, b.height, fill=False, ec="tab:blue", lw=1, ls="--"))
            if layout.black is not None:
                b = layout.black
                ax.add_patch(Rectangle((b.x0, b.y0), b.width, b.height, fill=False, ec="white", lw=1, ls="--"))
            for p in layout.patches:
                b = p.box
                ax.add_patch(Rectangle((b.x0, b.y0), b.width, b.height, fill=False, ec="yellow", lw=0.8))
                ax.text(b.x0 + 2, b.y0 + 2, f"{p.coats:g}", color="yellow", fontsize=6, va="top")
        ax.set_title("photo and layout (blue: paper, white: black, yellow: patches)", fontsize=8, loc="left")
        ax.axis("off")
        ax2 = fig.add_axes([0.52, 0.5 * top, 0.46, 0.38 * top])
        _more(ax2, coats, more)
    ax = fig.add_axes([0.1, 0.03, 0.88, (0.42 if photo is not None else 0.75) * top])
    _pairs(ax, groups, "patches: observed (left half) | fitted (right half)")
    if photo is None:
        ax2 = fig.add_axes([0.1, 0.8 * top, 0.88, 0.1 * top])
        _more(ax2, coats, more)
    _save(fig, path)


def _more(ax, coats: np.ndarray, more: list[tuple[str, np.ndarray]]) -> None:
    for r, (ground, pred) in enumerate(more):
        for c, rgb in enumerate(pred):
            ax.add_patch(Rectangle((c, -r * 1.2), 0.9, 1, color=_display(rgb)))
        ax.text(-0.1, -r * 1.2 + 0.5, f"over {ground}", ha="right", va="center", fontsize=7)
    for c, x in enumerate(coats):
        ax.text(c + 0.45, 1.05, f"{x:g}", ha="center", va="bottom", fontsize=7)
    ax.set_xlim(-1.6, len(coats))
    ax.set_ylim(-(len(more) - 1) * 1.2 - 0.1, 1.5)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title("the fitted pigment at more coats", fontsize=8, loc="left")


def save_table_report(path: str | os.PathLike, fit: Any, table: Any, held_out: Any = None) -> None:
    """Write a PNG report of a `TableFit`: each pigment's rows, measured vs fitted.

    `held_out`, an optional second `MeasurementTable`, is drawn too (its
    captions marked with `*`): rows the fit did not see.
    """
    groups = []
    for name in fit.names:
        items = []
        for tab, mark in ((table, ""), (held_out, "*")):
            if tab is None:
                continue
            rows = np.flatnonzero(tab.pigment == name)
            if len(rows) == 0:
                continue
            pred = fit.predict(name, tab.amount[rows], tab.ground[rows])
            de = fit.evaluate(tab.select(tab.pigment == name))
            for i, r in enumerate(rows):
                items.append((tab.amount[r], f"{tab.amount[r]:g}{mark}\n{tab.ground[r]}", tab.rgb[r], pred[i], de[i]))
        items.sort(key=lambda t: (t[1].split("\n")[1], t[0]))
        groups.append((name, [t[1:] for t in items]))
    n_cols = max(len(items) for _, items in groups)
    fig = _figure(figsize=(2.0 + 0.75 * n_cols, 0.6 + 1.3 * len(groups)))
    ax = fig.add_axes([0.14, 0.02, 0.85, 0.9])
    extra = " (* held out)" if held_out is not None else ""
    _pairs(ax, groups, f"measured (left half) | fitted (right half){extra}; model: "
                       f"{', '.join(f'{k}={v}' for k, v in fit.model.describe().items())}", step=2.0)  # fmt: skip
    _save(fig, path)


def _mixture_rows(fit: Any, m: Any, rows: Sequence[int]) -> list[tuple[str, Any, Any, float]]:
    """Squares of table rows: caption, measured and predicted linear sRGB, CIEDE2000."""
    pred = fit.library.predict(m)
    measured = m.values @ np.asarray(fit.library.observation.to_rgb) if m.spectral else m.values
    return [("\n".join(m.row_text(r)), measured[r], pred.linear_srgb[r], float(fit.delta_e[r])) for r in rows]


def save_mixture_report(path: str | os.PathLike, fit: Any, m: Any, per_row: int = 10) -> None:
    """Write a PNG report of a `MixtureFit` of table `m`: the worst rows and a sample of the others (measured |
    predicted squares), the CIEDE2000 of single paints and mixtures, and each pair's mean CIEDE2000."""
    de, mix = np.asarray(fit.delta_e), np.asarray(m.is_mixture)
    order = np.argsort(-de)
    worst = order[: 2 * per_row]
    rest = np.setdiff1d(np.arange(len(m)), worst)
    sample = rest[np.linspace(0, len(rest) - 1, min(2 * per_row, len(rest))).astype(int)] if len(rest) else rest
    squares = _mixture_rows(fit, m, [*worst, *sample])
    groups = [(label, squares[k * per_row : (k + 1) * per_row]) for k, label in
              enumerate(["worst", "", "others", ""]) if squares[k * per_row : (k + 1) * per_row]]  # fmt: skip
    fig = _figure(figsize=(2.0 + 0.75 * per_row, 3.2 + 1.3 * len(groups)))
    ax = fig.add_axes([0.08, 0.38, 0.9, 0.58])
    s = fit.summary()
    _pairs(ax, groups, f"measured (left half) | predicted (right half); mean CIEDE2000 {s['mean_de2000']:.2f}, "
                       f"{100 * s['share_de_ab_5']:.1f}% within dE*ab 5", step=2.0)  # fmt: skip
    h = fig.add_axes([0.07, 0.07, 0.38, 0.24])
    bins = np.linspace(0, max(float(de.max()), 1e-3), 30)
    stack = np.asarray(m.is_stack)
    for sel, label in ((~mix & ~stack, "single paints"), (mix & ~stack, "mixtures"), (stack, "glaze stacks")):
        if sel.any():
            h.hist(de[sel], bins, alpha=0.6, label=f"{label} (mean {de[sel].mean():.2f})")
    h.set_xlabel("CIEDE2000")
    h.legend(fontsize=7)
    b = fig.add_axes([0.55, 0.07, 0.43, 0.24])
    pairs = sorted({"+".join(sorted(set(p))) for p, x in zip(m.pigments, mix) if x})
    means = [float(np.mean([d for d, p, x in zip(de, m.pigments, mix) if x and "+".join(sorted(set(p))) == q]))
             for q in pairs]  # fmt: skip
    b.bar(range(len(pairs)), means, color="0.4")
    b.set_xticks(range(len(pairs)), pairs, rotation=90, fontsize=5)
    b.set_ylabel("mean CIEDE2000", fontsize=8)
    b.set_title("per mixed pair", fontsize=8, loc="left")
    _save(fig, path)


def save_image_report(path: str | os.PathLike, fit: Any, targets: Sequence[Any], scenes: Sequence[Any]) -> None:
    """Write a PNG report of an `ImageFit`: per view the target, the start, the fit and their difference, and the loss.

    `targets` and `scenes` are what `fit_image` was given (paths or arrays; Scenes).
    """
    scenes = list(scenes) * (len(targets) if len(scenes) == 1 else 1)
    n = len(targets)
    fig = _figure(figsize=(13, 2.8 * n + 0.4))
    axes = fig.subplots(n, 5, squeeze=False)
    for i, (t, sc) in enumerate(zip(targets, scenes)):
        if isinstance(t, (str, os.PathLike)):
            target, _ = read_image(t)
        else:
            target = _display(t)
        start = _display(np.asarray(render(sc, fit.start_params)))
        fitted = _display(np.asarray(render(sc, fit.params)))
        diff = np.abs(fitted - target).max(axis=-1)
        for ax, img, title in ((axes[i, 0], target, "target"), (axes[i, 1], start, "start"),
                               (axes[i, 2], fitted, "fitted")):  # fmt: skip
            ax.imshow(np.clip(img, 0, 1))
            ax.set_title(f"view {i}: {title}" if n > 1 else title, fontsize=8)
            ax.axis("off")
        im = axes[i, 3].imshow(diff, cmap="magma", vmin=0, vmax=max(float(diff.max()), 1 / 255))
        axes[i, 3].set_title(f"|fitted - target| (sRGB), rms {fit.rms[i]:.3g}", fontsize=8)
        axes[i, 3].axis("off")
        fig.colorbar(im, ax=axes[i, 3], fraction=0.046)
        if i == 0:
            ax = axes[0, 4]
            ax.semilogy(range(1, len(fit.history) + 1), np.maximum(fit.history, 1e-16), "o-", ms=3)
            ax.set_xlabel("step", fontsize=8)
            ax.set_ylabel("rms residual", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.set_title(f"{fit.solver}: {'converged' if fit.converged else 'did not converge'} in {fit.iterations} steps",
                         fontsize=8)  # fmt: skip
        else:
            axes[i, 4].axis("off")
    fig.suptitle("fitted: " + ", ".join(fit.fitted), fontsize=9)
    fig.tight_layout()
    _save(fig, path)
