"""Glaze stacks: what stacks over white and black grounds tell a fit, and how well held-out stacks are predicted.

    python benchmarks/bench_stacks.py [--only generated,ntu] [--noise 0.002] [--seed 0]

Prints Markdown tables:

1. **generated**: a table made by a known palette (the four NTU paints of `data/libraries/ntu-four.json`,
   pair terms dropped) with Gaussian noise of `--noise` on the reflectance: single paints at 0.02 and 0.05
   over the paper ("white") and a flat black ground of reflectance 0.03, and glaze stacks `A/B` (B over A)
   at 0.03/0.03 over both grounds for half of the ordered pairs (seeded). Fitted (`fit_mixtures`, spectral,
   default model) as (a) single paints over white only, (b) single paints over white and black, (c) (a)
   plus the stacks, (d) (b) plus the stacks; then each fit's K and S against the truth (median over
   pigments and bands of |log(fit/true)|, the 90th percentile too) and its CIEDE2000 on held-out stacks:
   the other half of the ordered pairs, at 0.02/0.04 and 0.04/0.02, and three-layer stacks `A/B/C`, over
   both grounds. The RGB route (`r,g,b` of the same rows) for (a) and (c).
2. **ntu**: the library fitted to NTU (`data/libraries/ntu-four.json`) predicting glazes of its paints
   over its paper. NTU measured no stacks, so there is nothing to score: the predictions' ranges, that each
   is finite and in [0, 1], that a glaze is no brighter than its top layer alone over the paper (what lies
   beneath it is darker than the paper), and how much the order of the layers matters.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import sys
import tempfile
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diffwash import colorimetry, library, measurements  # noqa: E402
from diffwash.fit import fit_mixtures  # noqa: E402
from diffwash.fit.tables._mixfit import residuals  # noqa: E402

LIB = ROOT / "data" / "libraries" / "ntu-four.json"
BLACK = 0.03


def _truth() -> library.Library:
    lib = library.load_library(LIB)
    pal = lib.palette.__class__(K=lib.palette.K, S=lib.palette.S, law=lib.palette.law, weights=lib.palette.weights,
                                names=lib.palette.names, wavelengths=lib.palette.wavelengths)  # no pair terms
    grounds = {"paper": lib.grounds["paper"], "black": np.full(len(lib.grounds["paper"]), BLACK)}
    return library.Library(palette=pal, grounds=grounds, observation=lib.observation, k2=lib.k2)


def _rows(truth, rng) -> dict[str, list[tuple[str, str, str]]]:
    names = truth.names
    ordered = list(itertools.permutations(names, 2))
    order = rng.permutation(len(ordered))
    train = [ordered[i] for i in order[: len(ordered) // 2]]
    test = [ordered[i] for i in order[len(ordered) // 2 :]]
    single = lambda g: [(p, f"{a:g}", g) for p in names for a in (0.02, 0.05)]  # noqa: E731
    stacks = [(f"{a}/{b}", "0.03/0.03", g) for a, b in train for g in ("paper", "black")]
    held = [(f"{a}/{b}", x, g) for a, b in test for x in ("0.02/0.04", "0.04/0.02") for g in ("paper", "black")]
    triples = list(itertools.permutations(names, 3))[::4]
    held += [(f"{a}/{b}/{c}", "0.02/0.02/0.02", g) for a, b, c in triples for g in ("paper", "black")]
    return {"white": single("paper"), "black": single("black"), "stacks": stacks, "held": held}


def _write(path: Path, truth, rows, rng, noise: float, rgb: bool) -> None:
    q = truth.predict([r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows])
    grounds = {g: truth.grounds[g] for g in ("paper", "black")}
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        if rgb:
            w.writerow(["pigment", "amount", "ground", "r", "g", "b"])
            for g, v in grounds.items():
                w.writerow([g, 0, g, *np.round(255 * np.asarray(colorimetry.srgb_encode(v @ truth.observation.to_rgb)), 3)])
            lin = np.clip(q.linear_srgb * (1 + noise * rng.standard_normal(q.linear_srgb.shape)), 0, 1)
            vals = 255 * np.asarray(colorimetry.srgb_encode(jnp.asarray(lin)))
        else:
            w.writerow(["pigment", "amount", "ground", *(f"{b:g}" for b in truth.observation.wavelengths)])
            for g, v in grounds.items():
                w.writerow([g, 0, g, *v])
            vals = np.clip(q.reflectance + noise * rng.standard_normal(q.reflectance.shape), 1e-4, None)
        for r, v in zip(rows, vals):
            w.writerow([*r, *np.round(v, 6)])


def _kserr(fit, truth) -> tuple[float, float, float, float]:
    """Median and 90th percentile of |log(fit/true)| of K and of S over pigments and bands."""
    lib = fit.library
    idx = [lib.names.index(n) for n in truth.names]
    out = []
    for a, b in ((lib.palette.K, truth.palette.K), (lib.palette.S, truth.palette.S)):
        e = np.abs(np.log(np.asarray(a, np.float64)[idx] / np.asarray(b, np.float64)))
        out += [float(np.median(e)), float(np.percentile(e, 90))]
    return tuple(out)


def generated(noise: float, seed: int, routes: list[str]) -> None:
    truth = _truth()
    rng = np.random.default_rng(seed)
    rows = _rows(truth, rng)
    cases = {"(a) singles over white": ["white"], "(b) singles over white and black": ["white", "black"],
             "(c) (a) + stacks over white and black": ["white", "stacks"],
             "(d) (b) + stacks over white and black": ["white", "black", "stacks"]}  # fmt: skip
    print(f"\n### Generated table (ntu-four, noise {noise} reflectance, seed {seed}): "
          f"{len(rows['stacks'])} training stacks, {len(rows['held'])} held-out stacks\n")
    for rgb in [r == "rgb" for r in routes]:
        print(f"\n{'RGB (sRGB 8-bit, relative noise)' if rgb else 'spectral (41 bands)'}\n")
        print("| table | rows | fit s | median, p90 abs log K err | median, p90 abs log S err | held-out stacks: "
              "mean, p90 dE2000 |\n| --- | --- | --- | --- | --- | --- |")
        with tempfile.TemporaryDirectory() as d:
            held = Path(d) / "held.csv"
            _write(held, truth, rows["held"], np.random.default_rng(seed + 1), noise, rgb)
            mh = measurements.read_measurements(held)
            for label, parts in cases.items():
                if rgb and "black" in parts:
                    continue
                table = Path(d) / "t.csv"
                _write(table, truth, [r for p in parts for r in rows[p]], np.random.default_rng(seed + 2), noise, rgb)
                m = measurements.read_measurements(table)
                t0 = time.perf_counter()
                fit = fit_mixtures(m)
                t = time.perf_counter() - t0
                de, _ = residuals(fit.library, mh)
                ke, kp, se, sp = _kserr(fit, truth)  # an RGB fit is spectral too, on the same 10 nm grid
                print(f"| {label} | {len(m)} | {t:.1f} | {ke:.3f}, {kp:.3f} | {se:.3f}, {sp:.3f} | "
                      f"{de.mean():.2f}, {np.percentile(de, 90):.2f} |")


def ntu() -> None:
    lib = library.load_library(LIB)
    names = lib.names
    pig, amt = [], []
    for a, b in itertools.permutations(names, 2):
        for x in ("0.02/0.02", "0.05/0.05", "0.1/0.02"):
            pig.append(f"{a}/{b}")
            amt.append(x)
    pred = lib.predict(pig, amt, ["paper"] * len(pig))
    alone = lib.predict([p.split("/")[k] for p in pig for k in (0, 1)],
                        [x.split("/")[k] for x in amt for k in (0, 1)], ["paper"] * 2 * len(pig))  # fmt: skip
    R = pred.reflectance
    Ra = alone.reflectance.reshape(len(pig), 2, -1)
    darker = np.all(R <= Ra[:, 1] + 1e-6, axis=1)  # the top layer over something darker than the paper
    print(f"\n### NTU four-paint library (no stacks measured: plausibility only)\n\n{len(pig)} glazes (12 ordered "
          f"pairs x 3 amounts) over its paper: finite {bool(np.all(np.isfinite(R)))}, reflectance in "
          f"[{R.min():.4f}, {R.max():.4f}], L* {pred.lab[:, 0].min():.1f}-{pred.lab[:, 0].max():.1f}; no brighter "
          f"than the top layer alone over the paper in any band: {int(darker.sum())}/{len(pig)}; B over A differs from A over B "
          f"by {_order_gap(lib):.2f} mean dE2000 (0.05/0.05).")


def _order_gap(lib) -> float:
    pairs = list(itertools.combinations(lib.names, 2))
    ab = lib.predict([f"{a}/{b}" for a, b in pairs], ["0.05/0.05"] * len(pairs), ["paper"] * len(pairs))
    ba = lib.predict([f"{b}/{a}" for a, b in pairs], ["0.05/0.05"] * len(pairs), ["paper"] * len(pairs))
    return float(np.mean(colorimetry.delta_e_2000(jnp.asarray(ab.lab), jnp.asarray(ba.lab))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="generated,ntu")
    ap.add_argument("--noise", type=float, default=0.002)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--routes", default="spectral,rgb", help="which fits of the generated tables")
    a = ap.parse_args()
    only = a.only.split(",")
    if "ntu" in only:
        ntu()
    if "generated" in only:
        generated(a.noise, a.seed, a.routes.split(","))


if __name__ == "__main__":
    main()
