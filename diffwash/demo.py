"""The demo: diffwash end to end on bundled data, as a technical artist's first session.

1. Fit a pigment to a phone photo of its swatch card (`fit.fit_swatches`).
2. Put it in a scene as the wash and fit the shading constants to a target
   image (`fit.fit_image`).
3. Bake the LUT (`lut.bake`), export the real-time shaders and the WebGL2
   viewer (`export`), and draw a frame through them with OpenGL
   (`preview.render`).
4. Write a one-page report of it all.

The bundled data (`diffwash/data/demo`, made by `data/make_demo.py`) are a
swatch card of a pigment that is not in the library, a 10k-triangle knot and a
target image painted with constants the demo has to find; `truth.json` says
what they were, so the report can show how close the fits come.
"""

from __future__ import annotations

import os
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure  # not pyplot: the caller's backend (a notebook's) stays as it is

from . import fit, lut, preview
from ._errors import DiffwashError
from ._export import export
from ._io import atomic_folder, read_image, read_json, save_figure, write_json, write_png
from ._render import render
from ._scene import load_scene
from ._version import __version__
from .colorimetry import to_display

__all__ = ["DemoResult", "run", "DATA", "FIT", "MARKER"]

#: The file by which the demo recognises a folder it wrote (and may replace).
MARKER = ".diffwash-demo"
#: The shading constants the demo fits to the target image.
FIT = ("gain", "bias", "k_wash", "k_unlit", "shininess", "wash_reduction")


def _data() -> Path:
    return Path(str(resources.files("diffwash") / "data" / "demo"))


DATA = _data()


@dataclass
class DemoResult:
    """What the demo wrote and measured.

    **Fields:** `folder`; `files` (name -> path, in the order written);
    `swatch` (the `SwatchFit`), `image` (the `ImageFit`); `truth` (what the
    bundled data were made with); `preview_renderer` (the OpenGL renderer, or
    why there was none); `seconds` per step.
    """

    folder: Path
    files: dict[str, Path] = field(default_factory=dict)
    swatch: Any = None
    image: Any = None
    truth: dict[str, Any] = field(default_factory=dict)
    preview_renderer: str = ""
    seconds: dict[str, float] = field(default_factory=dict)


class _Steps:
    """A progress display: one line per step, with its time."""

    def __init__(self, total: int, out: Callable[[str], None] | None):
        self.total, self.n, self.out = total, 0, out

    def start(self, what: str) -> float:
        self.n += 1
        if self.out:
            self.out(f"[{self.n}/{self.total}] {what} ...")
        return time.perf_counter()

    def done(self, t0: float, note: str = "") -> float:
        dt = time.perf_counter() - t0
        if self.out:
            self.out(f"      done in {dt:.1f} s{': ' + note if note else ''}")
        return dt


def run(
    folder: str | os.PathLike = "diffwash-demo",
    *,
    progress: bool | Callable[[str], None] = True,
    force: bool = False,
) -> DemoResult:
    """Run the demo, writing everything into `folder`, whole or not at all.

    Everything is written into a temporary folder beside `folder`, renamed to
    `folder` at the end: a failure (a full disk) leaves nothing behind.

    **Arguments:**

    - `folder`: the output folder. It must not exist, be empty, or hold a
      previous demo (recognised by its `MARKER` file), which is replaced.
    - `progress`: print a line per step (True), stay quiet (False), or call
      `progress(line)`.
    - `force`: write into a folder that holds other files too (the demo's
      files replace those of the same names; the others are left alone).

    **Returns:**

    A `DemoResult`.
    """
    out: Callable[[str], None] | None
    if progress is True:
        out = lambda s: print(s, flush=True)  # noqa: E731
    elif progress is False:
        out = None
    else:
        out = progress
    folder = Path(folder)
    merge = _may_write(folder, force)
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DiffwashError(f"cannot create the output folder: {e.strerror}", file=folder) from None
    with atomic_folder(folder, merge=merge) as work:
        res = DemoResult(folder=work, truth=read_json(DATA / "truth.json"))
        _run_steps(res, _Steps(6, out))
        if not merge:  # the demo owns the whole folder: a later demo may replace it
            (work / MARKER).write_text(f"written by diffwash {__version__} demo; `diffwash demo` may replace this "
                                       "folder\n", encoding="utf-8")  # fmt: skip
    res.files = {name: folder / p.relative_to(work) for name, p in res.files.items()}
    res.folder = folder
    return res


def _may_write(folder: Path, force: bool) -> bool:
    """Whether the demo may write `folder`, and whether into other files (True: merge) or whole (False)."""
    if not folder.exists():
        return False
    if not folder.is_dir():
        raise DiffwashError("exists and is not a folder", file=folder)
    if not any(folder.iterdir()) or (folder / MARKER).is_file():
        return False
    if not force:
        raise DiffwashError(f"is not empty and holds no {MARKER} marker (the demo did not write it); choose "
                            "another folder, or use --force to write into it anyway", file=folder)  # fmt: skip
    return True


def _run_steps(res: DemoResult, steps: _Steps) -> None:
    """The demo's six steps, writing into `res.folder`."""
    folder, out = res.folder, steps.out

    # 1. The pigment, from the swatch card.
    t = steps.start("fitting the pigment's K and S to the swatch-card photo (card.jpg)")
    for name in ("card.jpg", "card.json", "knot.ply", "target.png"):
        shutil.copyfile(DATA / name, folder / name)
        res.files[name] = folder / name
    swatch = fit.fit_swatches(folder / "card.jpg", folder / "card.json", name="Quinacridone Gold")
    swatch.save(folder / "pigment.json")
    res.files["pigment.json"] = folder / "pigment.json"
    card, _ = read_image(folder / "card.jpg")
    fit.save_swatch_report(folder / "swatch-fit.png", swatch, photo=card, layout=fit.read_layout(folder / "card.json"))
    res.files["swatch-fit.png"] = folder / "swatch-fit.png"
    res.swatch = swatch
    res.seconds["swatch fit"] = steps.done(
        t, f"mean CIEDE2000 {swatch.mean_delta_e:.2f} over {len(swatch.patches)} patches, "
        f"{'converged' if swatch.converged else 'NOT converged'} in {swatch.iterations} steps"
    )

    # 2. The shading constants, from the target image.
    t = steps.start(f"fitting {', '.join(FIT)} to the target image (target.png)")
    start = read_json(DATA / "scene.json")
    start["wash"] = {"pigment": "pigment.json"}
    write_json(folder / "scene.json", start)
    res.files["scene.json"] = folder / "scene.json"
    scene = load_scene(folder / "scene.json")

    def step_line(i: int, loss: float) -> None:
        if out and (i <= 3 or i % 5 == 0):
            out(f"      step {i:3d}  rms residual {loss:.3e}")

    image_fit = fit.fit_image(folder / "target.png", scene, FIT, progress=step_line)
    image_fit.save(folder / "fitted-scene.json")
    res.files["fitted-scene.json"] = folder / "fitted-scene.json"
    res.image = image_fit
    fit.save_image_report(folder / "image-fit.png", image_fit, [folder / "target.png"], [scene])
    res.files["image-fit.png"] = folder / "image-fit.png"
    res.seconds["image fit"] = steps.done(
        t, f"{'converged' if image_fit.converged else 'NOT converged'} in {image_fit.iterations} steps, "
        f"rms residual {image_fit.rms[0]:.1e}"
    )
    _realtime_steps(res, steps, load_scene(folder / "fitted-scene.json"))


def _realtime_steps(res: DemoResult, steps: _Steps, fitted: Any) -> None:
    """Steps 3-6: bake the LUT, export, draw an OpenGL frame, write the report."""
    folder = res.folder
    t = steps.start("baking the 256x256 LUT (lut.png + lut.json)")
    table = lut.bake(fitted, 256)
    for p in lut.save(folder / "lut.png", table):
        res.files[p.name] = p
    res.seconds["bake"] = steps.done(t)

    t = steps.start("exporting the WebGL2 shaders, the mesh and viewer.html (export/)")
    written = export(fitted, folder / "export", target="webgl2", overwrite=True)
    res.files["export/"] = folder / "export"
    res.seconds["export"] = steps.done(t, f"{len(written)} files")

    t = steps.start("drawing a frame through the exported shaders with OpenGL (preview.png)")
    frame = None
    try:
        frame = preview.render(fitted, lut=table)
        res.preview_renderer = preview.renderer_name()
    except Exception as e:  # no OpenGL here: say so, keep going
        res.preview_renderer = f"no OpenGL ({str(e).splitlines()[0] if str(e) else type(e).__name__})"
    if frame is not None:
        write_png(folder / "preview.png", frame)
        res.files["preview.png"] = folder / "preview.png"
    res.seconds["preview"] = steps.done(t, res.preview_renderer)

    t = steps.start("writing the one-page report (report.png)")
    fitted_img = to_display(render(fitted))
    _report(folder / "report.png", res, table, frame, fitted_img)
    res.files["report.png"] = folder / "report.png"
    res.seconds["report"] = steps.done(t)


def _report(path: Path, res: DemoResult, table: Any, frame: np.ndarray | None, fitted_img: np.ndarray) -> None:
    """One page: the card and its fit, the target and its fit, the LUT and the OpenGL frame."""
    fig = Figure(figsize=(16, 10.5), dpi=100)
    grid = fig.add_gridspec(3, 4, height_ratios=[1, 1, 1], hspace=0.45, wspace=0.25)
    fig.suptitle("diffwash demo: swatch photo -> pigment -> shading fit -> LUT -> real-time shader", fontsize=15)
    _report_swatch_row(fig, grid, res)
    _report_image_row(fig, grid, res, fitted_img)
    _report_realtime_row(fig, grid, res, table, frame)
    save_figure(path, fig, facecolor="white")


def _report_swatch_row(fig: Figure, grid: Any, res: DemoResult) -> None:
    """Row 1: the card, its patches photographed and fitted, and the pigment against the truth."""
    swatch, truth_p = res.swatch, res.truth["pigment"]
    card, _ = read_image(res.folder / "card.jpg")
    ax = fig.add_subplot(grid[0, 0])
    ax.imshow(card)
    ax.set_title("1. the swatch-card photo (card.jpg)")
    ax.axis("off")

    ax = fig.add_subplot(grid[0, 1])
    coats = sorted({p.coats for p in swatch.patches})
    grounds = [g for g in ("paper", "black") if any(p.ground == g for p in swatch.patches)]
    cells = np.ones((2 * len(grounds), len(coats), 3))
    for p in swatch.patches:
        i, j = 2 * grounds.index(p.ground), coats.index(p.coats)
        cells[i, j], cells[i + 1, j] = to_display(p.observed), to_display(p.fitted)
        ax.text(j, i + 0.5, f"ΔE {p.delta_e:.2f}", ha="center", va="center", fontsize=7, color="white")
    ax.imshow(cells, aspect="auto", interpolation="nearest")
    ax.set_yticks(range(2 * len(grounds)), [f"{g}: {w}" for g in grounds for w in ("photo", "fitted")], fontsize=8)
    ax.set_xticks(range(len(coats)), [f"{c:g}" for c in coats])
    ax.set_xlabel("coats")
    ax.set_title(f"patches, photo vs fitted\nmean CIEDE2000 {swatch.mean_delta_e:.2f}")

    ax = fig.add_subplot(grid[0, 2:])
    x = np.arange(3)
    K, S = np.asarray(swatch.pigment.K), np.asarray(swatch.pigment.S)
    ax.bar(x - 0.3, truth_p["K"], 0.2, color="0.75", label="K true")
    ax.bar(x - 0.1, K, 0.2, color="tab:red", label="K fitted")
    ax.bar(x + 0.1, truth_p["S"], 0.2, color="0.55", label="S true")
    ax.bar(x + 0.3, S, 0.2, color="tab:blue", label="S fitted")
    ax.set_xticks(x, ["red", "green", "blue"])
    ax.set_title("the fitted pigment against the card's truth (per coat)")
    ax.legend(ncols=4, fontsize=8)


def _report_image_row(fig: Figure, grid: Any, res: DemoResult, fitted_img: np.ndarray) -> None:
    """Row 2: the target, the fitted render, the loss curve and the constants against the truth."""
    image = res.image
    target, _ = read_image(res.folder / "target.png")
    for col, img, title in ((0, target, "2. the target image (target.png)"), (1, fitted_img, "rendered with the fitted constants")):
        ax = fig.add_subplot(grid[1, col])
        ax.imshow(img)
        ax.set_title(title)
        ax.axis("off")
    ax = fig.add_subplot(grid[1, 2])
    ax.semilogy(np.arange(1, len(image.history) + 1), image.history, "o-", ms=3)
    ax.set_xlabel("solver step")
    ax.set_ylabel("rms residual (linear RGB)")
    ax.set_title(f"{image.solver}: {'converged' if image.converged else 'not converged'} in {image.iterations} steps")
    ax = fig.add_subplot(grid[1, 3])
    ax.axis("off")
    rows = [["", "start", "fitted", "true"]]
    for k in FIT:
        rows.append([k, f"{float(np.squeeze(image.start[k])):.3f}", f"{float(np.squeeze(image.fitted[k])):.3f}",
                     f"{res.truth['constants'][k]:.3f}"])  # fmt: skip
    tab = ax.table(cellText=rows, loc="center", cellLoc="center", colWidths=[0.4, 0.2, 0.2, 0.2])
    tab.auto_set_font_size(False)
    tab.set_fontsize(10)
    tab.scale(1.1, 1.6)
    ax.set_title("shading constants")


def _report_realtime_row(fig: Figure, grid: Any, res: DemoResult, table: Any, frame: np.ndarray | None) -> None:
    """Row 3: the LUT, the OpenGL frame, and what was written."""
    ax = fig.add_subplot(grid[2, 0])
    ax.imshow(to_display(table.colour), extent=[0, 1, 1, 0])
    ax.set_xlabel("wash thickness / wash_max")
    ax.set_ylabel("unlit thickness / unlit_max")
    ax.set_title("3. the baked LUT (lut.png)")
    ax = fig.add_subplot(grid[2, 1])
    if frame is not None:
        ax.imshow(np.clip(frame, 0, 1))
        ax.set_title("4. OpenGL frame through the exported shader")
    else:
        ax.text(0.5, 0.5, res.preview_renderer, ha="center", va="center", wrap=True)
    ax.axis("off")
    ax = fig.add_subplot(grid[2, 2:])
    ax.axis("off")
    files = [n for n in res.files]
    text = (
        "files written:\n  " + "\n  ".join(", ".join(files[i : i + 4]) for i in range(0, len(files), 4))
        + f"\n\nopen export/viewer.html in a WebGL2 browser to orbit the knot\nOpenGL: {res.preview_renderer}"
        + "\n\ntimes: " + ", ".join(f"{k} {v:.1f} s" for k, v in res.seconds.items())
    )  # fmt: skip
    ax.text(0, 1, text, va="top", family="monospace", fontsize=9)


def main_summary(res: DemoResult, stream: Any = None) -> None:
    """Print what the demo wrote and where to look (on `stream`, default the standard output of the moment)."""
    stream = sys.stdout if stream is None else stream
    total = sum(res.seconds.values())
    print(f"\nwrote {len(res.files)} results to {res.folder}/ in {total:.0f} s:", file=stream)
    for name, p in res.files.items():
        print(f"  {p}", file=stream)
    print(f"\nthe one-page report: {res.folder / 'report.png'}", file=stream)
    viewer = (res.folder / "export" / "viewer.html").resolve()
    print(f"the real-time viewer: open {viewer.as_uri()} in a browser (WebGL2)", file=stream)
