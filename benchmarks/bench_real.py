"""Real paint that diffwash was not developed on: fit a table's training rows, predict its held-out rows.

    python benchmarks/bench_real.py [--data data/kimera-paintmixing] [--keep DIR] [--loo]

Runs the command line as a user would: `diffwash fit-swatch --table TRAIN -o lib.json` (with
`--allow-unconverged`, saying whether the fit converged), then
`diffwash predict lib.json --table QUERIES` on the held-out rows' `pigment,amount,ground`, and compares the
predicted CIELAB (D65, CIE 1931 2-degree) with the measured spectra seen the same way. Prints a Markdown
table: mean and max CIEDE2000, share within CIE dE*ab 5, for diffwash and for two baselines that need no
fit, computed from the training table's single-paint rows (each paint's one measured layer):

- geometric mean of the paints' reflectances, weighted by the mixture's amount fractions;
- a one-constant K/S average: K/S = (1 - R)^2 / 2R of each paint's layer (taken as opaque), averaged with
  the amount fractions, back to reflectance R = 1 + K/S - sqrt((K/S)^2 + 2 K/S);
- Mixbox (pymixbox, CC BY-NC: a peer only, never a dependency) on the paints' sRGB, when it is installed.

Then one row per held-out sample (measured and predicted CIELAB, each method's CIEDE2000). `--loo` also
runs leave-one-out over every mixture row of the whole table (`kimera-all.csv`): each fit lacks one tint and
predicts it (one fit per tint, about a minute each on 2 cores).

The data set and its fixed split are described in data/kimera-paintmixing/README.md (its tables are made
by that folder's convert.py from the upstream files).
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diffwash import colorimetry, measurements, spectral  # noqa: E402

DATA = ROOT / "data" / "kimera-paintmixing"


def _run(*args: str) -> tuple[float, str]:
    """Run the command line in a fresh process: its wall time and what it printed."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "diffwash", *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"diffwash {' '.join(args)} failed:\n{done.stdout}{done.stderr}")
    print(done.stdout.strip().replace("\n", "\n    "), file=sys.stderr)
    return time.perf_counter() - t0, done.stdout


def _queries(held: measurements.Measurements, path: Path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground"])
        for p, a, g in zip(held.pigments, held.amounts, held.ground):
            w.writerow(["+".join(p), "+".join(f"{x:g}" for x in a), g])


def _predicted_lab(path: Path) -> np.ndarray:
    with open(path, newline="") as f:
        return np.array([[float(r["L*"]), float(r["a*"]), float(r["b*"])] for r in csv.DictReader(f)])


def _singles(train: measurements.Measurements) -> dict[str, np.ndarray]:
    """Each paint's single-layer reflectance in the training table (its largest amount)."""
    best: dict[str, tuple[float, np.ndarray]] = {}
    for p, a, v in zip(train.pigments, train.amounts, train.values):
        if len(p) == 1 and a[0] >= best.get(p[0], (-1.0, None))[0]:
            best[p[0]] = (a[0], v)
    return {k: v for k, (_, v) in best.items()}


def _fractions(amounts) -> np.ndarray:
    a = np.asarray(amounts, float)
    return a / a.sum()


def geometric_mean(single: dict, pigments, amounts) -> np.ndarray:
    c = _fractions(amounts)
    return np.exp(sum(ci * np.log(np.maximum(single[p], 1e-4)) for p, ci in zip(pigments, c)))


def one_constant(single: dict, pigments, amounts) -> np.ndarray:
    c = _fractions(amounts)
    r = {p: np.clip(single[p], 1e-4, 0.999) for p in pigments}
    ks = sum(ci * (1 - r[p]) ** 2 / (2 * r[p]) for p, ci in zip(pigments, c))
    return 1 + ks - np.sqrt(ks * ks + 2 * ks)


def _mixbox_lab(single: dict, held: measurements.Measurements, obs) -> np.ndarray | None:
    try:
        import mixbox  # benchmark-only peer (pymixbox, CC BY-NC)
    except ImportError:
        return None
    out = []
    for p, a in zip(held.pigments, held.amounts):
        if len(p) != 2:
            return None
        rgb = [np.clip(np.asarray(colorimetry.srgb_encode(obs.linear_srgb(single[n]))), 0, 1) * 255 for n in p]
        mixed = np.asarray(mixbox.lerp(tuple(rgb[0]), tuple(rgb[1]), _fractions(a)[1]), float) / 255
        out.append(np.asarray(colorimetry.srgb_to_lab(mixed)))
    return np.array(out)


def _scores(lab_pred: np.ndarray, lab_true: np.ndarray) -> tuple[float, float, float]:
    de00 = np.asarray(colorimetry.delta_e_2000(lab_pred, lab_true))
    deab = np.linalg.norm(lab_pred - lab_true, axis=-1)
    return float(de00.mean()), float(de00.max()), float(np.mean(deab < 5))


def predict_held_out(train_csv: Path, held: measurements.Measurements, work: Path) -> tuple[dict, float, float, bool]:
    """Fit `train_csv` and predict `held` through the command line: {method: CIELAB per row}, fit and predict
    seconds, and whether the fit converged (an unconverged fit is written anyway, `--allow-unconverged`, and
    counted)."""
    train = measurements.read_measurements(train_csv)
    obs = spectral.observation(held.wavelengths)
    lib, q, pred = work / "lib.json", work / "queries.csv", work / "predicted.csv"
    t_fit, said = _run("fit-swatch", "--table", str(train_csv), "-o", str(lib), "--allow-unconverged")
    _queries(held, q)
    t_pred, _ = _run("predict", str(lib), "--table", str(q), "-o", str(pred))
    single = _singles(train)
    labs = {"diffwash": _predicted_lab(pred)}
    for name, f in (("geometric mean", geometric_mean), ("one-constant K/S", one_constant)):
        labs[name] = np.asarray(obs.lab(np.array([f(single, p, a) for p, a in zip(held.pigments, held.amounts)])))
    mb = _mixbox_lab(single, held, obs)
    if mb is not None:
        labs["Mixbox"] = mb
    return labs, t_fit, t_pred, "did not converge" not in said


def _subset_csv(src: Path, keep, dst: Path) -> None:
    """Write the lines of `src` whose data-row index (0-based, ground rows included) is in `keep`."""
    lines = src.read_text().splitlines()
    dst.write_text("\n".join([lines[0]] + [ln for i, ln in enumerate(lines[1:]) if i in keep]) + "\n")


def leave_one_out(data: Path, work: Path) -> tuple[dict, np.ndarray, list[str]]:
    """Every mixture row of kimera-all.csv predicted by a fit of all the other rows."""
    src = data / "kimera-all.csv"
    lines = src.read_text().splitlines()[1:]
    mixed = [i for i, ln in enumerate(lines) if "+" in ln.split(",")[0]]
    labs: dict[str, list] = {}
    truth, names, converged = [], [], 0
    for i in mixed:
        _subset_csv(src, set(range(len(lines))) - {i}, work / "train.csv")
        _subset_csv(src, {i} | {j for j, ln in enumerate(lines) if ln.split(",")[1] == "0"}, work / "held.csv")
        held = measurements.read_measurements(work / "held.csv")
        got, _, _, ok = predict_held_out(work / "train.csv", held, work)
        converged += ok
        for k, v in got.items():
            labs.setdefault(k, []).append(v[0])
        truth.append(np.asarray(spectral.observation(held.wavelengths).lab(held.values))[0])
        names.append("+".join(held.pigments[0]))
    return {k: np.array(v) for k, v in labs.items()}, np.array(truth), names, converged


def _print_tables(title: str, labs: dict, truth: np.ndarray, names: list[str], note: str) -> None:
    print(f"### {title}\n")
    print("| method | rows | mean dE2000 | max dE2000 | within dE*ab 5 |")
    print("| --- | --- | --- | --- | --- |")
    for name, lab in labs.items():
        mean, mx, share = _scores(lab, truth)
        print(f"| {name} | {len(truth)} | {mean:.2f} | {mx:.2f} | {100 * share:.0f}% |")
    print(f"\n{note}\n")
    print("| row | measured L*, a*, b* | diffwash L*, a*, b* | " + " | ".join(f"{k} dE2000" for k in labs) + " |")
    print("| --- | --- | --- | " + " | ".join("---" for _ in labs) + " |")
    de = {k: np.asarray(colorimetry.delta_e_2000(v, truth)) for k, v in labs.items()}
    for i, n in enumerate(names):
        fmt = ", ".join(f"{x:.1f}" for x in truth[i]), ", ".join(f"{x:.1f}" for x in labs["diffwash"][i])
        print(f"| {n} | {fmt[0]} | {fmt[1]} | " + " | ".join(f"{de[k][i]:.2f}" for k in labs) + " |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DATA, help="folder with the kimera-*.csv tables")
    ap.add_argument("--keep", type=Path, default=None, help="keep the library and predictions in this folder")
    ap.add_argument("--loo", action="store_true", help="also leave each mixture row out in turn")
    args = ap.parse_args()
    train_csv, held_csv = args.data / "kimera-train.csv", args.data / "kimera-heldout.csv"
    if not train_csv.exists():
        raise SystemExit(f"{train_csv} is missing: run data/kimera-paintmixing/convert.py (see its README)")
    held = measurements.read_measurements(held_csv)
    truth = np.asarray(spectral.observation(held.wavelengths).lab(held.values))
    with tempfile.TemporaryDirectory() as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        labs, t_fit, t_pred, ok = predict_held_out(train_csv, held, work)
        names = ["+".join(p) for p in held.pigments]
        _print_tables(f"Fixed split: the held-out rows of `{held_csv.name}`", labs, truth, names,
                      f"diffwash: fit {t_fit:.0f} s ({'converged' if ok else 'did NOT converge'}), "
                      f"predict {t_pred:.0f} s, each in a fresh process.")  # fmt: skip
        if args.loo:
            labs, truth, names, n_ok = leave_one_out(args.data, work)
            _print_tables("Leave one mixture row out (one fit per row)", labs, truth, names,
                          f"diffwash's fits converged in {n_ok} of {len(names)} folds (the others were written "
                          "with `--allow-unconverged` and scored all the same).")  # fmt: skip


if __name__ == "__main__":
    main()
