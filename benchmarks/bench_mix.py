"""Mixing real paint: fit and predict time, peak memory, and scores on pairs held out of the fit.

    python benchmarks/bench_mix.py [--folds 4] [--only speed,seen,spectral,weights,rgb,mixbox]

Prints Markdown tables, on the NTU WPSM measurements in data/ntu-wpsm/:

1. Speed (float32, CPU): `diffwash.fit.fit_mixtures` on the whole spectral table (1,858 rows, 13 paints,
   41 bands) in this process, JIT included (target <= 600 s on 2 cores, goal <= 30 s), its peak resident
   memory, and `diffwash predict` of 500 rows in a fresh process with an empty compilation cache
   (target <= 20 s, goal <= 3 s).
2. Leave-pairs-out cross-validation (`diffwash.fit.pair_folds`: each fold holds out the mixtures of a
   quarter of the 62 pairs; single paints always train): share of held-out rows within CIE dE*ab 5 and mean
   CIEDE2000, for each model term (spectral Duncan; + a mixing weight per pigment; the RGB table fitted as
   smooth spectra) and for Mixbox (pymixbox, CC BY-NC: a benchmark peer only, never a dependency) mixing the
   measured colours of the two paints, each at the mixture's total amount, at the ratio of their amounts.
3. Rows of measured pairs held out at random (a fifth of the mixture rows, seeds 0 and 1; every pair is still
   seen mixed in training, as in the dataset's own test split): the same scores with and without the pair
   terms (`MixModel.pairs`). The pair terms' ridge and number of bumps were chosen on seed 1.

Timings taken while other work runs on the machine are provisional.
"""

from __future__ import annotations

import argparse
import csv
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diffwash import colorimetry, measurements  # noqa: E402
from diffwash.fit import MixModel, fit_mixtures, pair_folds, score_library  # noqa: E402

DATA = ROOT / "data" / "ntu-wpsm"
SPECTRAL = DATA / "ntu-spectral-train.csv"
RGB = DATA / "ntu-rgb-train.csv"


def speed() -> None:
    m = measurements.read_measurements(SPECTRAL)
    t0 = time.perf_counter()
    fit = fit_mixtures(m)
    t_fit = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    with tempfile.TemporaryDirectory() as tmp:
        lib, q, out = Path(tmp, "lib.json"), Path(tmp, "q.csv"), Path(tmp, "p.csv")
        fit.save(lib)
        rows = [("+".join(p), "+".join(f"{a:g}" for a in amt)) for p, amt in zip(m.pigments, m.amounts)][:500]
        with open(q, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["pigment", "amount", "ground"])
            w.writerows([(p, a, "paper") for p, a in rows])
        env = dict(os.environ, PYTHONPATH=str(ROOT), DIFFWASH_CACHE_DIR=str(Path(tmp, "cache")))
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "diffwash", "predict", str(lib), "--table", str(q), "-o", str(out)],
                       check=True, env=env, capture_output=True)  # fmt: skip
        t_pred = time.perf_counter() - t0
    print("| what | time (s) | note |\n|---|---|---|")
    print(f"| fit whole spectral table ({len(m)} rows), JIT included | {t_fit:.1f} | {fit.iterations} LM steps, "
          f"converged {fit.converged}, peak RSS {peak:.0f} MiB |")
    print(f"| `diffwash predict` 500 rows, fresh process, empty cache | {t_pred:.1f} | |")


def _mixbox_score(m: measurements.Measurements, test: np.ndarray) -> dict[str, float]:
    import mixbox  # benchmark-only peer (pymixbox, CC BY-NC)

    single = {(p[0], round(sum(a), 6)): v for p, a, v, mix in zip(m.pigments, m.amounts, m.values, m.is_mixture)
              if not mix}  # fmt: skip
    lab_m, lab_p = [], []
    for i in np.flatnonzero(test):
        (p1, p2), (a1, a2) = m.pigments[i], m.amounts[i]
        total = round(a1 + a2, 6)
        c = []
        for p in (p1, p2):
            amts = [a for (q, a) in single if q == p]
            near = min(amts, key=lambda a: abs(a - total))
            c.append(tuple(int(round(255 * float(x))) for x in colorimetry.to_display(single[(p, near)])))
        mixed = np.asarray(mixbox.lerp(c[0], c[1], a2 / (a1 + a2)), float) / 255
        lab_p.append(np.asarray(colorimetry.srgb_to_lab(mixed)))
        lab_m.append(np.asarray(colorimetry.linear_srgb_to_lab(m.values[i])))
    lab_m, lab_p = np.array(lab_m), np.array(lab_p)
    de = np.asarray(colorimetry.delta_e_2000(lab_m, lab_p))
    return {"rows": len(de), "share_de_ab_5": float(np.mean(np.linalg.norm(lab_m - lab_p, axis=1) <= 5)),
            "mean_de2000": float(de.mean())}  # fmt: skip


def cross_validate(name: str, path: Path, model: MixModel | None, folds: int) -> None:
    m = measurements.read_measurements(path)
    scores, t0 = [], time.perf_counter()
    for train, test in pair_folds(m, folds, seed=0):
        if model is None:
            scores.append(_mixbox_score(m, test))
        else:
            scores.append(score_library(fit_mixtures(m.select(train), model=model).library, m.select(test)))
    n = sum(s["rows"] for s in scores)
    share = sum(s["share_de_ab_5"] * s["rows"] for s in scores) / n
    mean = sum(s["mean_de2000"] * s["rows"] for s in scores) / n
    print(f"| {name} | {path.name} | {n} | {100 * share:.1f}% | {mean:.2f} | {time.perf_counter() - t0:.0f} s |",
          flush=True)  # fmt: skip


def seen_pairs(seed: int) -> None:
    """Held-out rows of pairs the fit saw mixed: one fit, scored with its pair terms and without them."""
    import dataclasses

    import equinox as eqx

    m = measurements.read_measurements(SPECTRAL)
    held = np.asarray(m.is_mixture) & (np.random.default_rng(seed).random(len(m)) < 0.2)
    t0 = time.perf_counter()
    fit = fit_mixtures(m.select(~held))
    seconds = time.perf_counter() - t0
    duncan = dataclasses.replace(fit.library, palette=eqx.tree_at(lambda p: p.pairs, fit.library.palette, None,
                                                                  is_leaf=lambda x: x is None))  # fmt: skip
    for name, lib in (("Duncan (the same pigments, no pair terms)", duncan), ("with pair terms", fit.library)):
        s = score_library(lib, m.select(held))
        print(f"| {seed} | {name} | {s['rows']} | {100 * s['share_de_ab_5']:.1f}% | {s['mean_de2000']:.2f} | "
              f"{seconds:.0f} s |", flush=True)  # fmt: skip


MODELS = {
    "spectral": ("spectral Duncan, amount law per pigment, CIEDE2000 refinement (ridge 3)", SPECTRAL, MixModel()),
    "logspectral": ("spectral Duncan, log-reflectance loss only", SPECTRAL, MixModel(loss="spectral")),
    "ridge1": ("spectral Duncan, CIEDE2000 refinement, ridge 1", SPECTRAL, MixModel(ridge=1.0)),
    "weights": ("spectral + mixing weight per pigment", SPECTRAL, MixModel(weights=True)),
    "surface": ("spectral + Saunderson k2", SPECTRAL, MixModel(surface=True)),
    "rgb": ("RGB table as smooth spectra, Duncan", RGB, MixModel()),
    "mixbox": ("Mixbox on measured single colours", RGB, None),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folds", type=int, default=4)
    ap.add_argument("--only", default="speed,seen,spectral,weights,rgb,mixbox")
    args = ap.parse_args()
    only = args.only.split(",")
    if "speed" in only:
        speed()
    if "seen" in only:
        print("\nRows of measured pairs held out at random (a fifth of the mixtures):\n")
        print("| seed | model | rows | within dE*ab 5 | mean dE2000 | fit time |\n|---|---|---|---|---|---|")
        for seed in (0, 1):
            seen_pairs(seed)
    cv = [k for k in MODELS if k in only]
    if cv:
        print(f"\nLeave-pairs-out cross-validation, {args.folds} folds (held-out pairs' mixtures):\n")
        print("| model | table | rows | within dE*ab 5 | mean dE2000 | time |\n|---|---|---|---|---|---|")
        for k in cv:
            cross_validate(*MODELS[k][:2], MODELS[k][2], args.folds)


if __name__ == "__main__":
    main()
