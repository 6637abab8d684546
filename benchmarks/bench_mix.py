"""Mixing real paint: fit and predict time, peak memory, and scores on pairs held out of the fit.

    python benchmarks/bench_mix.py [--folds 4] [--only speed,seen,seen-rgb,spectral,weights,rgb,mixbox,single,paper,small,never-mixed]

Prints Markdown tables, on the NTU WPSM measurements in data/ntu-wpsm/:

1. Speed (float32, CPU): `diffwash.fit.fit_mixtures` on the whole spectral table (1,858 rows, 13 paints,
   41 bands) in this process, JIT included (target <= 600 s on 2 cores, goal <= 30 s), its peak resident
   memory, and `diffwash predict` of 500 rows in a fresh process with an empty compilation cache
   (target <= 20 s, goal <= 3 s).
2. Leave-pairs-out cross-validation (`diffwash.fit.pair_folds`: each fold holds out the mixtures of a
   quarter of the 62 pairs; single paints always train): share of held-out rows within CIE dE*ab 5 and mean
   CIEDE2000, the share held by the predictions' 90% regions (`de2000_90`), for each model term (spectral Duncan
   with the held-out pairs' terms inferred from the measured pairs', the default; `noinfer`: those pairs at
   Duncan's law; + a mixing weight per pigment; the RGB table fitted as smooth spectra, with its pair terms
   and inferred ones, and, `rgbduncan`, without), on the fold draws of
   `--seeds` (default 0), and for Mixbox (pymixbox, CC BY-NC: a benchmark peer only, never a dependency) mixing the
   measured colours of the two paints, each at the mixture's total amount, at the ratio of their amounts.
3. Rows of measured pairs held out at random (a fifth of the mixture rows, seeds 0 and 1; every pair is still
   seen mixed in training, as in the dataset's own test split): the same scores with and without the pair
   terms (`MixModel.pairs`). The pair terms' ridge and number of bumps were chosen on seed 1. `seen-rgb`: the
   same on the 8-bit sRGB table (its pigments smooth spectra, its pair terms fitted in CIEDE2000 of its rows).
4. `single`: single paints at held-out amounts through the command line, as a user would: the single-paint rows
   of a table with each paint's 2nd, 4th, ... amounts held out (the split of docs/fitting.md), `diffwash
   fit-swatch --table` of the rest, `diffwash predict` of the held-out rows; mean CIEDE2000 of the predicted
   L*a*b* against the measured. Spectral (`ntu-spectral-train.csv`, 13 paints) and 8-bit sRGB
   (`primaries-P1-P7.csv`, 7 paints).
5. `paper`: the paper's split emulated: a random fifth of all rows held out (seeds 0 and 1), the default fit of the
   rest; whether it converged, its training and held-out scores.
6. `small`: fit time of small tables with many band parameters (default settings, JIT included): a generated
   table of 40 paints, each once over two light grounds, 77 bands (400-780 nm, 5 nm), and 80 NTU rows resampled
   to the same grid.
7. `never-mixed` (not in the default run): notebooks 06 and 07's held-out rows, P1+P12 and P12+P7 (32 rows),
   predicted by the default fit (without pair terms, as the notebooks) of growing tables: the four paints
   P1, P4, P7 and P12 (P12 never measured mixed: notebook 07); the four with one more paint X and X's mixtures
   with P12, for each X the table mixes with P12; the four with all five such paints; the whole table less the
   two pairs (notebook 06). Mean CIEDE2000 of the held-out rows, the share held by their 90% regions.

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

from diffwash import colorimetry, km, measurements  # noqa: E402
from diffwash.fit import MixModel, fit_mixtures, pair_folds, score_library  # noqa: E402

DATA = ROOT / "data" / "ntu-wpsm"
SPECTRAL = DATA / "ntu-spectral-train.csv"
RGB = DATA / "ntu-rgb-train.csv"
PRIMARIES = DATA / "primaries-P1-P7.csv"


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


def _held_by_regions(lib, m: measurements.Measurements) -> float:
    """Share of a table's rows whose measured colour lies within the prediction's `de2000_90` (NaN: none)."""
    from diffwash.fit.tables._mixfit import measured_lab

    pred = lib.predict(m)
    if pred.de2000_90 is None:
        return float("nan")
    lab_p = pred.lab if m.spectral else np.asarray(colorimetry.linear_srgb_to_lab(pred.linear_srgb))
    de = np.asarray(colorimetry.delta_e_2000(measured_lab(m, lib.observation), lab_p))
    return float(np.mean(de <= pred.de2000_90))


def cross_validate(name: str, path: Path, model: MixModel | None, folds: int, seed: int = 0) -> None:
    m = measurements.read_measurements(path)
    scores, t0 = [], time.perf_counter()
    for train, test in pair_folds(m, folds, seed=seed):
        if model is None:
            scores.append(_mixbox_score(m, test) | {"held": float("nan")})
        else:
            t1 = time.perf_counter()
            lib = fit_mixtures(m.select(train), model=model).library
            scores.append(score_library(lib, m.select(test)) | {"held": _held_by_regions(lib, m.select(test))})
            s = scores[-1]
            print(f"  fold {len(scores)}: {s['rows']} rows, {100 * s['share_de_ab_5']:.1f}%, {s['mean_de2000']:.2f}, "
                  f"held by the 90% regions {100 * s['held']:.1f}% ({time.perf_counter() - t1:.0f} s)", flush=True)
    n = sum(s["rows"] for s in scores)
    share = sum(s["share_de_ab_5"] * s["rows"] for s in scores) / n
    mean = sum(s["mean_de2000"] * s["rows"] for s in scores) / n
    held = sum(s["held"] * s["rows"] for s in scores) / n
    regions = "-" if np.isnan(held) else f"{100 * held:.1f}%"
    print(f"| {name} | {path.name} | {seed} | {n} | {100 * share:.1f}% | {mean:.2f} | {regions} | {time.perf_counter() - t0:.0f} s |",
          flush=True)  # fmt: skip


def seen_pairs(seed: int, path: Path = SPECTRAL) -> None:
    """Held-out rows of pairs the fit saw mixed: one fit, scored with its pair terms and without them."""
    import dataclasses

    import equinox as eqx

    m = measurements.read_measurements(path)
    held = np.asarray(m.is_mixture) & (np.random.default_rng(seed).random(len(m)) < 0.2)
    t0 = time.perf_counter()
    fit = fit_mixtures(m.select(~held))
    seconds = time.perf_counter() - t0
    duncan = dataclasses.replace(fit.library, palette=eqx.tree_at(lambda p: p.pairs, fit.library.palette, None,
                                                                  is_leaf=lambda x: x is None))  # fmt: skip
    for name, lib in (("Duncan (the same pigments, no pair terms)", duncan), ("with pair terms", fit.library)):
        s = score_library(lib, m.select(held))
        regions = f"{100 * _held_by_regions(lib, m.select(held)):.1f}%" if lib is fit.library else "-"
        print(f"| {path.name} | {seed} | {name} | {s['rows']} | {100 * s['share_de_ab_5']:.1f}% | {s['mean_de2000']:.2f} | {regions} | "
              f"{seconds:.0f} s |", flush=True)  # fmt: skip


def _cli(*args: str, cwd: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-m", "diffwash", *args], cwd=cwd, env=env, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"diffwash {' '.join(args)} failed: {r.stdout}{r.stderr}")


def _held_out_amounts(m: measurements.Measurements) -> np.ndarray:
    """Single-paint rows whose amount is a paint's 2nd, 4th, ... (docs/fitting.md's split), as a row mask."""
    held = np.zeros(len(m), bool)
    for name in m.names:
        ix = [i for i, (p, mix) in enumerate(zip(m.pigments, m.is_mixture)) if not mix and p[0] == name]
        order = sorted(ix, key=lambda i: sum(m.amounts[i]))
        held[order[1::2]] = True
    return held


def _write_table(path: Path, m: measurements.Measurements, rows: np.ndarray) -> None:
    """Rows of `m` as a table file: spectral as reflectance, RGB as 8-bit sRGB (as read)."""
    bands = [f"{w:g}" for w in m.wavelengths] if m.spectral else ["r", "g", "b"]
    fmt = (lambda v: [f"{x:.6f}" for x in v]) if m.spectral else (  # noqa: E731
        lambda v: [str(int(x)) for x in np.round(255 * np.asarray(colorimetry.srgb_encode(v)))])
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground", *bands])
        for g, v in m.grounds.items():
            w.writerow([g, 0, g, *fmt(v)])
        for i in np.flatnonzero(rows):
            w.writerow(["+".join(m.pigments[i]), "+".join(f"{a:g}" for a in m.amounts[i]), m.ground[i],
                        *fmt(m.values[i])])  # fmt: skip


def primaries_table(dest: Path) -> Path:
    """`primaries-P1-P7.csv` (the NTU dataset's own layout) as a table in the shared format, 8-bit sRGB."""
    from diffwash.fit import read_ntu_wpsm

    t = read_ntu_wpsm(PRIMARIES)
    enc = lambda lin: np.round(255 * np.asarray(colorimetry.srgb_encode(lin))).astype(int)  # noqa: E731
    with open(dest, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground", "r", "g", "b"])
        w.writerow(["paper", 0, "paper", *enc(t.paper)])
        w.writerows([(n, f"{a:g}", g, *enc(c)) for n, a, g, c in zip(t.pigment, t.amount, t.ground, t.rgb)])
    return dest


def single_paints(path: Path, linear: bool = False) -> None:
    """Single paints' held-out amounts through `fit-swatch --table` and `predict` (section 4 of the docstring)."""
    m = measurements.read_measurements(path)
    single = ~np.asarray(m.is_mixture)
    held = _held_out_amounts(m)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _write_table(tmp / "train.csv", m, single & ~held)
        t0 = time.perf_counter()
        _cli("fit-swatch", "--table", "train.csv", "-o", "lib.json", *(["--linear"] if linear else []), cwd=tmp)
        t_fit = time.perf_counter() - t0
        with open(tmp / "q.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["pigment", "amount", "ground"])
            w.writerows([("+".join(m.pigments[i]), "+".join(f"{a:g}" for a in m.amounts[i]), m.ground[i])
                         for i in np.flatnonzero(held)])  # fmt: skip
        _cli("predict", "lib.json", "--table", "q.csv", "-o", "pred.csv", cwd=tmp)
        with open(tmp / "pred.csv", newline="") as f:
            lab = np.array([[float(r["L*"]), float(r["a*"]), float(r["b*"])] for r in csv.DictReader(f)])
    measured = measurements_lab(m)[held]
    de = np.asarray(colorimetry.delta_e_2000(measured, lab))
    print(f"| {path.name} | {int(np.sum(single & ~held))} | {len(de)} | {de.mean():.2f} | {np.median(de):.2f} | "
          f"{de.max():.2f} | {t_fit:.0f} s |", flush=True)  # fmt: skip


def measurements_lab(m: measurements.Measurements) -> np.ndarray:
    if m.spectral:
        return np.asarray(m.observation().lab(m.values), np.float64)
    return np.asarray(colorimetry.linear_srgb_to_lab(m.values), np.float64)


def paper_split(seed: int) -> None:
    """A random fifth of all rows held out, the default fit of the rest (section 5 of the docstring)."""
    m = measurements.read_measurements(SPECTRAL)
    held = np.random.default_rng(seed).random(len(m)) < 0.2
    t0, c0 = time.perf_counter(), time.process_time()
    fit = fit_mixtures(m.select(~held))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    s, h = fit.summary(), score_library(fit.library, m.select(held))
    print(f"| {seed} | {int(np.sum(~held))} / {h['rows']} | {fit.converged} ({fit.iterations} steps) | "
          f"{100 * s['share_de_ab_5']:.1f}%, {s['mean_de2000']:.2f} | {100 * h['share_de_ab_5']:.1f}%, "
          f"{h['mean_de2000']:.2f} | {wall:.0f} s ({cpu:.0f} s CPU) |", flush=True)  # fmt: skip


def generated_table(path: Path, paints: int = 40, seed: int = 0) -> None:
    """A table of `paints` made-up paints (smooth random log K, log S), each once over two light grounds, 77 bands
    (400-780 nm, 5 nm), 0.5% noise: 2 ground rows and 2 x `paints` paint rows."""
    rng = np.random.default_rng(seed)
    wl = np.arange(400, 781, 5.0)
    x = (wl - 400) / 380
    bumps = np.exp(-0.5 * ((x[:, None] - np.linspace(0, 1, 6)[None]) / 0.15) ** 2)
    grounds = {"paper": 0.86 + 0.04 * x, "cream": 0.70 + 0.15 * x}
    rows = [(g, "0", g, v) for g, v in grounds.items()]
    for i in range(paints):
        K = np.exp(rng.normal(0, 1.0) + bumps @ rng.normal(0, 1.5, 6))
        S = np.exp(rng.normal(-1, 0.8) + bumps @ rng.normal(0, 0.5, 6))
        for g, v in grounds.items():
            R = np.asarray(km.over(*km.layer(K, S, 1.0), v)) * (1 + rng.normal(0, 0.005, len(wl)))
            rows.append((f"Q{i + 1}", "0.05", g, np.clip(R, 0.001, 1)))
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground", *(f"{v:g}" for v in wl)])
        w.writerows([(p, a, g, *(f"{r:.5f}" for r in v)) for p, a, g, v in rows])


def resampled_ntu(path: Path, rows: int = 80, seed: int = 0) -> None:
    """`rows` rows of the NTU spectral table (single paints and mixtures, at random), interpolated to 400-780 nm in
    5 nm steps (77 bands)."""
    m = measurements.read_measurements(SPECTRAL)
    pick = np.zeros(len(m), bool)
    pick[np.random.default_rng(seed).choice(len(m), rows, replace=False)] = True
    wl = np.arange(400, 781, 5.0)
    res = lambda v: np.interp(wl, m.wavelengths, v)  # noqa: E731
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground", *(f"{v:g}" for v in wl)])
        for g, v in m.grounds.items():
            w.writerow([g, 0, g, *(f"{x:.6f}" for x in res(v))])
        for i in np.flatnonzero(pick):
            w.writerow(["+".join(m.pigments[i]), "+".join(f"{a:g}" for a in m.amounts[i]), m.ground[i],
                        *(f"{x:.6f}" for x in res(m.values[i]))])  # fmt: skip


def small_tables() -> None:
    """Fit time of small tables with many band parameters (section 6 of the docstring)."""
    with tempfile.TemporaryDirectory() as tmp:
        for name, make in (("generated: 40 paints x 2 grounds", generated_table), ("NTU, 80 rows resampled", resampled_ntu)):
            path = Path(tmp, "t.csv")
            make(path)
            m = measurements.read_measurements(path)
            t0, c0 = time.perf_counter(), time.process_time()
            fit = fit_mixtures(m)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            print(f"| {name} | {len(m)} rows, {len(m.names)} paints, {len(m.wavelengths)} bands | {wall:.1f} s "
                  f"({cpu:.1f} s CPU) | {fit.converged} ({fit.iterations} steps) | {fit.summary()['mean_de2000']:.2f} |",
                  flush=True)  # fmt: skip


MODELS = {
    "spectral": ("spectral Duncan, amount law per pigment, CIEDE2000 refinement (ridge 3), unseen pairs' terms "
                 "inferred", SPECTRAL, MixModel()),
    "noinfer": ("spectral, unseen pairs at Duncan's law (no inferred pair terms)", SPECTRAL,
                MixModel(infer_pairs=False)),
    "noprior": ("spectral Duncan without the table's population priors", SPECTRAL,
                MixModel(scatter_spread=0.0, gamma_spread=0.0)),
    "logspectral": ("spectral Duncan, log-reflectance loss only", SPECTRAL, MixModel(loss="spectral")),
    "ridge1": ("spectral Duncan, CIEDE2000 refinement, ridge 1", SPECTRAL, MixModel(ridge=1.0)),
    "weights": ("spectral + mixing weight per pigment", SPECTRAL, MixModel(weights=True)),
    "surface": ("spectral + Saunderson k2", SPECTRAL, MixModel(surface=True)),
    "linearlaw": ("spectral Duncan, thickness proportional to amount (no fitted amount law)", SPECTRAL,
                  MixModel(gamma=False)),
    "rgb": ("RGB table as smooth spectra, pair terms, unseen pairs' terms inferred", RGB, MixModel()),
    "rgbduncan": ("RGB table as smooth spectra, Duncan for every mixture (the default before 2026-11-27)", RGB,
                  MixModel(pairs=False)),
    "mixbox": ("Mixbox on measured single colours", RGB, None),
}


def never_mixed() -> None:
    """Notebooks 06 and 07's held-out P12 pairs from tables that measure P12 mixed with more and more paints."""
    m = measurements.read_measurements(SPECTRAL)
    held = {("P1", "P12"), ("P12", "P7")}
    key = [tuple(sorted(set(p))) for p in m.pigments]
    test = np.array([k in held for k in key])
    four = {"P1", "P4", "P7", "P12"}
    partners = sorted({q for k in set(key) - held if "P12" in k and len(k) == 2 for q in k} - four)
    tables = [("P1, P4, P7, P12 (notebook 07)", set())] + [(f"+ {x} and {x}+P12", {x}) for x in partners]
    tables.append((f"+ {', '.join(partners)} and their mixtures with P12", set(partners)))
    for name, extra in tables:
        sel = np.array([set(p) <= four or (len(set(p)) == 1 and set(p) <= extra)
                        or ("P12" in p and set(p) <= extra | {"P12"}) for p in m.pigments])  # fmt: skip
        _never_mixed_row(name, m, sel & ~test, test)
    _never_mixed_row("the whole table less the two pairs (notebook 06)", m, ~test, test)


def _never_mixed_row(name: str, m: measurements.Measurements, train: np.ndarray, test: np.ndarray) -> None:
    t0 = time.perf_counter()
    fit = fit_mixtures(m.select(train), model=MixModel(pairs=False))
    h = score_library(fit.library, m.select(test))
    print(f"| {name} | {int(train.sum())} | {h['mean_de2000']:.2f} | {100 * h['share_de_ab_5']:.1f}% | "
          f"{100 * _held_by_regions(fit.library, m.select(test)):.1f}% | {time.perf_counter() - t0:.0f} s |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folds", type=int, default=4)
    ap.add_argument("--seeds", default="0", help="the cross-validation's fold draws (`pair_folds` seeds), e.g. 0,1,2")
    ap.add_argument("--only", default="speed,seen,spectral,weights,rgb,mixbox,single,paper,small")
    args = ap.parse_args()
    only = args.only.split(",")
    if "speed" in only:
        speed()
    seen = [path for k, path in (("seen", SPECTRAL), ("seen-rgb", RGB)) if k in only]
    if seen:
        print("\nRows of measured pairs held out at random (a fifth of the mixtures):\n")
        print("| table | seed | model | rows | within dE*ab 5 | mean dE2000 | held by the 90% regions | fit time |\n"
              "|---|---|---|---|---|---|---|---|")
        for path in seen:
            for seed in (0, 1):
                seen_pairs(seed, path)
    if "single" in only:
        print("\nSingle paints at held-out amounts, `fit-swatch --table` then `diffwash predict`:\n")
        print("| table | training rows | held-out rows | mean dE2000 | median | max | fit (CLI) |\n|---|---|---|---|---|---|---|")
        single_paints(SPECTRAL)
        with tempfile.TemporaryDirectory() as tmp:
            single_paints(primaries_table(Path(tmp, "primaries-P1-P7-table.csv")))
    if "paper" in only:
        print("\nThe paper's split emulated (a random fifth of all rows held out), default settings:\n")
        print("| seed | train / held-out rows | converged | train: within dE*ab 5, mean dE2000 | held out | fit time |")
        print("|---|---|---|---|---|---|")
        for seed in (0, 1):
            paper_split(seed)
    if "small" in only:
        print("\nSmall tables with many band parameters, default settings, JIT included:\n")
        print("| table | size | fit time | converged | mean dE2000 |\n|---|---|---|---|---|")
        small_tables()
    if "never-mixed" in only:
        print("\nNotebooks 06 and 07's held-out rows (P1+P12, P12+P7) as P12 is measured mixed with more paints:\n")
        print("| table | rows | mean dE2000 | within dE*ab 5 | held by the 90% regions | fit time |")
        print("|---|---|---|---|---|---|")
        never_mixed()
    cv = [k for k in MODELS if k in only]
    if cv:
        print(f"\nLeave-pairs-out cross-validation, {args.folds} folds (held-out pairs' mixtures):\n")
        print("| model | table | seed | rows | within dE*ab 5 | mean dE2000 | held by the 90% regions | time |\n"
              "|---|---|---|---|---|---|---|---|")
        for k in cv:
            for seed in (int(x) for x in args.seeds.split(",")):
                cross_validate(*MODELS[k][:2], MODELS[k][2], args.folds, seed)


if __name__ == "__main__":
    main()
