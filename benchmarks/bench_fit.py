"""Fitting: speed of the swatch, table and image fits, the command line cold, and accuracy on real paints.

    python benchmarks/bench_fit.py [--repeats 5] [--skip-cli]

Prints Markdown tables:

1. Speed, float32 on the CPU: warm time (median of REPEATS calls after a first one), compile time (the
   first call minus a warm one: JAX tracing and XLA compilation), peak resident memory of this process.
   Peers measured in the same run: the same residuals and Jacobian (jitted JAX) handed to SciPy's MINPACK
   Levenberg-Marquardt (`scipy.optimize.least_squares(method="lm")`), and for the image fit a single
   render of the scene (the unit a fit's cost is counted in).
   - swatch fit: `diffwash.fit.fit_swatches` on a generated JPEG swatch card (4 coat counts over paper and
     black, 360x264 px), from reading the photo to the diagnostics (target <= 0.5 s warm), with the
     default noise-weighted residuals (with intervals) and with unweighted CIE94 residuals;
   - image fit: `diffwash.fit.fit_image` on the sphere scene at 256x256 px, 10 parameters (gain, bias,
     k_wash, k_unlit, shininess, light (2 angles), paper (3)), from a start 20% off (target <= 2 s warm);
   - table fit: `diffwash.fit.fit_table` on the NTU training amounts (7 paints in one call), with the
     pigments run in turn (`batch="loop"`, the default on a CPU) and `jax.vmap`ped (`batch="vmap"`).
2. The command line end to end in a fresh process with an empty compilation cache
   (`DIFFWASH_CACHE_DIR` set to a new temporary folder), including JIT: `diffwash fit-swatch` with
   `--report` (target <= 10 s), `fit-swatch --table` (loop and vmap), `fit-image`; and `fit-swatch` again with the cache
   now filled.
3. Accuracy on generated swatch photos: each of the 12 seed pigments on a JPEG card with the default
   camera faults (`diffwash.swatchcard.CameraEffects()`), fitted from its 1, 2 and 4 coat patches,
   predicted at 3 and 5 coats over paper and black, CIEDE2000 against the true Kubelka-Munk colours
   (`benchmarks/bench_coverage.py` does this on many cards under harsher faults, with interval coverage).
4. Accuracy on real measurements (NTU WPSM, Winsor & Newton watercolours): each paint fitted at half of
   its amounts and predicted at the other half, mean CIEDE2000 per paint, for the plain per-pigment LM fit
   and the diffwash model, both directions of the split, and ablations of the model's parts.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import diffwash  # noqa: E402
from diffwash import colorimetry, pigments  # noqa: E402
from diffwash.fit import PLAIN, FitModel, fit_image, fit_swatches, fit_table, read_ntu_wpsm  # noqa: E402
from diffwash.swatchcard import make_swatch_card, save_swatch_card  # noqa: E402


NTU = ROOT / "data" / "ntu-wpsm" / "primaries-P1-P7.csv"  # shipped with the repository


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def timed(fn, repeats: int) -> tuple[float, float, object]:
    """(warm median, compile estimate, last result)."""
    t0 = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    warm = statistics.median(times)
    return warm, max(first - warm, 0.0), out


def minpack(residual, jacobian, y0: np.ndarray) -> callable:
    """A SciPy MINPACK LM run on jitted JAX residuals and Jacobian (the peer)."""
    from scipy.optimize import least_squares

    def run():
        return least_squares(lambda y: np.asarray(residual(y), np.float64), y0,
                             jac=lambda y: np.asarray(jacobian(y), np.float64), method="lm")  # fmt: skip

    return run


def bench_swatch(folder: Path, repeats: int) -> list[tuple]:
    import jax
    import jax.numpy as jnp

    from diffwash.fit._kmfit import residuals

    card = make_swatch_card(pigments.load("Quinacridone Rose"), coats=(1, 2, 3, 4), seed=1)
    save_swatch_card(card, folder / "card.jpg")
    layout = json.loads((folder / "card.json").read_text())
    warm, comp, fit = timed(lambda: fit_swatches(folder / "card.jpg", layout), repeats)
    rows = [("swatch fit (photo to pigment), noise-weighted with intervals (the default)", warm, comp, peak_rss_mb(),
             f"{fit.iterations} LM steps, mean dE00 {fit.mean_delta_e:.2f}")]  # fmt: skip
    cie94 = FitModel(thickness="linear", loss="cie94")
    w2, c2, f2 = timed(lambda: fit_swatches(folder / "card.jpg", layout, model=cie94), repeats)
    rows.append(("swatch fit, unweighted CIE94 residuals", w2, c2, peak_rss_mb(),
                 f"{f2.iterations} LM steps, mean dE00 {f2.mean_delta_e:.2f}"))  # fmt: skip
    # Peer: MINPACK on the same residuals (rows from this fit's patches).
    from diffwash.fit._kmfit import Rows

    obs = np.array([p.observed for p in fit.patches])
    grounds = np.array([fit.paper if p.ground == "paper" else fit.black for p in fit.patches])
    coats = np.array([p.coats for p in fit.patches])
    rw = Rows(amount=jnp.asarray(coats, jnp.float32), ground=jnp.asarray(grounds, jnp.float32),
              rgb=jnp.asarray(obs, jnp.float32), lo=jnp.zeros(obs.shape, bool), hi=jnp.zeros(obs.shape, bool),
              weight=jnp.ones(len(coats), jnp.float32))  # fmt: skip

    def flat(y):
        return {"log_K": y[:3], "log_S": y[3:]}

    r = jax.jit(lambda y: residuals(flat(y), (cie94, rw)))
    J = jax.jit(jax.jacfwd(lambda y: residuals(flat(y), (cie94, rw))))
    y0 = np.log(np.concatenate([fit.pigment.K * 1.5, fit.pigment.S * 0.7])).astype(np.float32)
    pw, pc, sol = timed(minpack(r, J, y0), repeats)
    rows.append(("  peer: SciPy MINPACK LM, the CIE94 residuals (solve only)", pw, pc, peak_rss_mb(),
                 f"{sol.nfev} evaluations"))  # fmt: skip
    return rows


def bench_image(repeats: int) -> list[tuple]:
    import equinox as eqx

    scene = diffwash.load_scene(ROOT / "data" / "scenes" / "sphere.json", size=(256, 256))
    target = np.asarray(diffwash.render(scene))
    p = scene.params
    start = eqx.tree_at(lambda q: (q.gain, q.bias, q.k_wash, q.k_unlit, q.shininess, q.light, q.paper), p,
                        (0.5, 0.55, 1.2, 1.2, 15.0, np.array([-0.6, 1.2, 0.8]), np.array([0.85, 0.85, 0.8])))  # fmt: skip
    names = ("gain", "bias", "k_wash", "k_unlit", "shininess", "light", "paper")
    warm, comp, fit = timed(lambda: fit_image(target, scene, names, start=start), repeats)
    err = max(float(np.max(np.abs(np.asarray(fit.fitted[n]) / np.asarray(getattr(p, n)) - 1)))
              for n in names if n != "light")  # fmt: skip
    rows = [("image fit, 256^2, 10 parameters", warm, comp, peak_rss_mb(),
             f"{fit.iterations} LM steps, max relative error {err:.1e}")]  # fmt: skip
    vis = diffwash.rasterize(scene)
    rw, rc, _ = timed(lambda: np.asarray(diffwash.render(scene, start, visibility=vis)), repeats)
    rows.append(("  peer: one render, 256^2 (visibility reused)", rw, rc, peak_rss_mb(), f"fit = {warm / rw:.0f} renders"))
    return rows


def ntu_split(table, first: int):
    rank = np.zeros(len(table), int)
    for n in table.names:
        ix = np.flatnonzero(table.pigment == n)
        rank[ix[np.argsort(table.amount[ix])]] = np.arange(len(ix))
    return table.select(rank % 2 == first), table.select(rank % 2 != first)


def bench_table(repeats: int) -> list[tuple]:
    train, _ = ntu_split(read_ntu_wpsm(NTU), 0)
    rows = []
    for batch, label in (("loop", "pigments in turn (the CPU default)"), ("vmap", "jax.vmap over pigments")):
        warm, comp, fit = timed(lambda: fit_table(train, batch=batch), repeats)
        rows.append((f"table fit, NTU (7 paints x 6 amounts), {label}", warm, comp, peak_rss_mb(),
                     f"steps {int(np.max(fit.iterations))} max"))  # fmt: skip
    return rows


def cli_run(args: list[str], cwd: Path, cache: str) -> float:
    env = {**os.environ, "DIFFWASH_CACHE_DIR": cache, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "diffwash", *args], cwd=cwd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"diffwash {' '.join(args)} failed:\n{r.stderr}")
    return dt


def bench_cli(folder: Path) -> list[tuple]:
    card = make_swatch_card(pigments.load("French Ultramarine"), coats=(1, 2, 3, 4), seed=2)
    save_swatch_card(card, folder / "cli.jpg")
    train, _ = ntu_split(read_ntu_wpsm(NTU), 0)
    lines = ["pigment,amount,ground,r,g,b", "paper,0,paper,240,240,235"]
    for n, a, g, c in zip(train.pigment, train.amount, train.ground, train.rgb):
        lines.append(f"{n},{a:g},{g}," + ",".join(str(int(x)) for x in np.round(255 * colorimetry.to_display(c))))
    (folder / "ntu.csv").write_text("\n".join(lines) + "\n")
    scene = json.loads((ROOT / "data" / "scenes" / "sphere.json").read_text())
    scene["mesh"] = str(ROOT / "data" / "meshes" / "sphere.ply")
    scene["image"] = {"width": 128, "height": 128}
    (folder / "truth.json").write_text(json.dumps(scene))
    from diffwash._io import write_png

    img = np.asarray(diffwash.render(diffwash.load_scene(folder / "truth.json")))
    write_png(folder / "target.png", np.asarray(colorimetry.srgb_encode(np.clip(img, 0, 1))), bits=16)
    (folder / "start.json").write_text(json.dumps({**scene, "gain": 0.5, "k_unlit": 1.2, "shininess": 15}))
    runs = [
        ("diffwash fit-swatch PHOTO --layout (cold)", ["fit-swatch", "cli.jpg", "--layout", "cli.json", "-o", "p.json"]),
        ("diffwash fit-swatch PHOTO --layout --report (cold)",
         ["fit-swatch", "cli.jpg", "--layout", "cli.json", "-o", "p.json", "--report", "r.png"]),
        ("diffwash fit-swatch --table (cold)", ["fit-swatch", "--table", "ntu.csv", "-o", "lib.json"]),
        ("diffwash fit-swatch --table --batch vmap (cold)",
         ["fit-swatch", "--table", "ntu.csv", "-o", "lib.json", "--batch", "vmap"]),
        ("diffwash fit-image, 128^2, 3 parameters (cold)",
         ["fit-image", "target.png", "--scene", "start.json", "--fit", "gain,k_unlit,shininess", "-o", "f.json", "--quiet"]),
    ]  # fmt: skip
    rows = []
    for label, args in runs:
        cache = tempfile.mkdtemp(prefix="diffwash-cache-")
        rows.append((label, cli_run(args, folder, cache)))
        if args[1] == "cli.jpg" and "--report" in args:
            rows.append(("diffwash fit-swatch PHOTO --layout --report (cache filled)", cli_run(args, folder, cache)))
    return rows


def bench_swatch_accuracy(folder: Path) -> list[tuple]:
    from diffwash import km
    from diffwash.fit._kmfit import delta_e_displayed

    rows = []
    for i, name in enumerate(pigments.names()):
        card = make_swatch_card(pigments.load(name), coats=(1, 2, 3, 4, 5), seed=i)
        save_swatch_card(card, folder / "acc.jpg")
        layout = json.loads((folder / "acc.json").read_text())
        layout["patches"] = [p for p in layout["patches"] if p["coats"] in (1, 2, 4)]
        fit = fit_swatches(folder / "acc.jpg", layout)
        errs = []
        for c in (3, 5):
            for ground in (card.paper, card.ink):
                R, T = km.layer(card.pigment.K, card.pigment.S, c)
                errs.append(float(delta_e_displayed(fit.predict([c], ground)[0], np.asarray(km.over(R, T, ground)))))
        rows.append((name, fit.mean_delta_e, float(np.mean(errs)), float(np.max(errs)), fit.converged))
    return rows


def bench_ntu() -> tuple[list[str], list[tuple]]:
    table = read_ntu_wpsm(NTU)
    variants = [
        ("plain LM (thickness = amount, sRGB residuals)", PLAIN),
        ("diffwash model (power-law thickness, CIEDE2000 residuals, prior)", FitModel()),
        ("  without the power law", FitModel(thickness="linear")),
        ("  with CIE94 instead of CIEDE2000 residuals (the photo fit's default)", FitModel(loss="cie94")),
        ("  with CIELAB instead of CIEDE2000 residuals", FitModel(loss="lab")),
        ("  with sRGB residuals", FitModel(loss="srgb")),
        ("  without the prior", FitModel(prior=0.0)),
        ("  plus Saunderson's surface correction (k1 = 0, k2 = 0.596)", FitModel(surface="saunderson")),
    ]
    rows = []
    for label, model in variants:
        res = []
        for first in (0, 1):
            train, test = ntu_split(table, first)
            fit = fit_table(train, model=model)
            d = fit.evaluate(test)
            per = [float(d[test.pigment == n].mean()) for n in table.names]
            res.append((float(d.mean()), per, bool(np.all(fit.converged))))
        rows.append((label, res))
    return table.names, rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--skip-cli", action="store_true")
    args = ap.parse_args()
    import jax

    print(f"diffwash {diffwash.__version__}, jax {jax.__version__}, {jax.devices()[0].platform}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}\n")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rows = bench_swatch(folder, args.repeats) + bench_image(max(args.repeats // 2, 2)) + bench_table(args.repeats)
        print("| fit | warm (s) | compile (s) | peak RSS (MB) | notes |")
        print("| --- | ---: | ---: | ---: | --- |")
        for label, warm, comp, rss, note in rows:
            print(f"| {label} | {warm:.3f} | {comp:.2f} | {rss:.0f} | {note} |")
        print()
        if not args.skip_cli:
            print("| command line, fresh process, empty compilation cache | wall (s) |")
            print("| --- | ---: |")
            for label, dt in bench_cli(folder):
                print(f"| {label} | {dt:.2f} |")
            print()
        acc = bench_swatch_accuracy(folder)
        print("Generated swatch photos (JPEG, default camera faults): fitted at 1, 2, 4 coats, predicted at 3 and 5\n")
        print("| pigment | fit dE00 (seen patches) | unseen coats: mean dE00 | max dE00 | converged |")
        print("| --- | ---: | ---: | ---: | --- |")
        for name, seen, mean, mx, ok in acc:
            print(f"| {name} | {seen:.2f} | {mean:.2f} | {mx:.2f} | {'yes' if ok else 'NO'} |")
        print(f"| all 12 | | {np.mean([a[2] for a in acc]):.2f} | {np.max([a[3] for a in acc]):.2f} | |\n")
    names, rows = bench_ntu()
    print("NTU WPSM held-out mean CIEDE2000 (train: 1st, 3rd, ... amounts of each paint; test: 2nd, 4th, ... "
          "incl. 0.16 mL; and the reverse split)\n")  # fmt: skip
    print("| model | held-out mean | reverse split | " + " | ".join(names) + " |")
    print("| --- | ---: | ---: | " + " | ".join("---:" for _ in names) + " |")
    for label, res in rows:
        (m0, per0, ok0), (m1, _, ok1) = res
        flag = "" if ok0 and ok1 else " (not all converged)"
        print(f"| {label}{flag} | {m0:.3f} | {m1:.3f} | " + " | ".join(f"{v:.2f}" for v in per0) + " |")


if __name__ == "__main__":
    main()
