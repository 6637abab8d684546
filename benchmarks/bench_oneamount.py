"""One amount per paint over two light grounds: predict mixtures never seen, against simple averages.

    python benchmarks/bench_oneamount.py [--seeds 0,1,2] [--only generated,ntu] [--paints 40] [--scatter 0]

The question of issue 20: a colour scientist measures another maker's paints, each brushed once over each of
two light grounds (the grounds measured bare), and wants the colours of mixtures of pairs and triples. This
prints Markdown tables of the mean CIEDE2000 (D65, CIE 1931 2-degree) of such mixtures held out of the fit,
for `diffwash.fit.fit_mixtures` (default settings) and three predictions that need no fit, each from the
paints' single layers over the same ground as the mixture:

- geometric mean of the paints' reflectances, weighted by the mixture's amount fractions;
- a one-constant K/S average: K/S = (1 - R)^2 / 2R of each paint's layer (taken as opaque), averaged with the
  amount fractions, back to R = 1 + K/S - sqrt((K/S)^2 + 2 K/S);
- Mixbox (pymixbox, CC BY-NC: a benchmark peer only, never a dependency; skipped when not installed): pairs by
  `mixbox.lerp`, triples by averaging latents.

1. `generated` ("another maker", `--paints` paints, 77 bands, 400-780 nm in 5 nm steps). Not diffwash's own
   model: the paints are made from real watercolours and measured through other physics, written here in
   NumPy (nothing of `diffwash.km` or `diffwash.mixing`):

   - each NTU paint's K and S per band (data/ntu-wpsm, its single paints at 11-12 amounts over paper) from a
     per-band least-squares fit of the two-constant Kubelka-Munk layer with thickness proportional to the
     amount (not diffwash's power law);
   - the maker's paints: an NTU paint's spectra shifted by up to 25 nm, K scaled by a random factor (log sd 0.3),
     S by another (log sd 1: transparent dyes to opaque body colours) and tilted, each brushed at its own
     thickness; plus two whites (high, flat S) and a black;
   - measured through: a Saunderson surface per paint (internal reflectance k2 in 0.35-0.6, a residual
     external term k1 in 0-0.02; a mixture's are its fractions' average), a brushed layer of uneven thickness
     (log-normal, sd 0.25, the reflectance averaged over it), mixtures that are not Duncan's (each pair's K and S
     scaled by random factors, log sd 0.15 and 0.3 at 1:1), and measurement noise (0.5% per band, 1% gain per
     sample, 0.002 absolute);
   - two light grounds: the NTU paper and a cream paper;
   - held out: 30 pairs and 14 triples of those paints (random fractions) over the white ground, never in the
     table, and the same 44 over the cream ground;
   - and 22 glaze stacks (`A/B`: paint B brushed over dry paint A, each at its own thickness) over each ground,
     measured through the same physics: each layer of its own uneven thickness, the top paint's surface, noise.
     No stack is in the table either; the simple peers have no stack rule, so the stacks' line compares with
     the top paint's own layer over the ground (what one sees if the lower layer is ignored) instead.
   - `--scatter S` shifts every made paint's log S by S: -2 a maker of transparent paint (inks, dye-based
     watercolour), +1 of opaque paint (gouache); 0, the default, is the table above.

2. `ntu` (real paint, the NTU watercolours, one ground only): each of the 13 paints once, at 0.06 mL over paper,
   is the whole table; held out, every two-paint mixture of the table whose total is 0.06 mL (198 rows, 62 pairs),
   and, apart, those at 0.03 and 0.12 mL (the amount law then comes from the prior alone).

Every figure is printed with its seed; timings are wall and CPU seconds of the fit in this process (JIT included).
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diffwash import _regions, colorimetry, library, measurements, spectral  # noqa: E402
from diffwash.fit import fit_mixtures  # noqa: E402
from diffwash.fit.tables import _posterior  # noqa: E402

NTU = ROOT / "data" / "ntu-wpsm" / "ntu-spectral-train.csv"
WL = np.arange(400, 781, 5.0)


# ---------------------------------------------------------------- the other maker's physics (NumPy only)


def km_layer(K, S, t):
    """Reflectance and transmittance of a Kubelka-Munk layer of optical depths K t, S t (hyperbolic solution)."""
    K, S = np.maximum(K, 1e-9), np.maximum(S, 1e-9)
    a = 1 + K / S
    b = np.sqrt(a * a - 1)
    x = np.minimum(b * S * t, 40.0)
    th, ch = np.tanh(x), np.cosh(x)
    R = th / (a * th + b)
    T = b / (ch * (a * th + b))
    return R, T


def over(R, T, g):
    return R + T * T * g / (1 - R * g)


def measured(K, S, t, ground, k1, k2, uneven=0.25):
    """What the other maker's spectrophotometer reads: a layer of uneven thickness (log-normal, Gauss-Hermite
    average) over the ground seen through a Saunderson surface (k1 external, k2 internal)."""
    x, w = np.polynomial.hermite_e.hermegauss(7)
    w = w / w.sum()
    g_in = ground / (1 - k2 + k2 * ground)  # the bare ground, as read through the same surface, is `ground`
    R = 0.0
    for xi, wi in zip(x, w):
        ti = t * np.exp(uneven * xi - 0.5 * uneven**2)
        R = R + wi * over(*km_layer(K, S, ti), g_in)
    return k1 + (1 - k1) * (1 - k2) * R / (1 - k2 * R)


def ntu_paints():
    """K, S per band (13 paints, NTU's 41 bands) of the NTU single paints: a per-band least-squares fit of
    `over(km_layer(K, S, a / 0.05), paper)` to each paint's 11-12 amounts (damped Gauss-Newton in log K, log S)."""
    m = measurements.read_measurements(NTU)
    paper = m.grounds["paper"]
    out = {}
    for name in m.names:
        rows = [i for i, p in enumerate(m.pigments) if list(p) == [name]]
        t = np.array([m.amounts[i][0] for i in rows]) / 0.05
        Y = np.log(np.array([m.values[i] for i in rows]) + 0.01)
        r = np.clip(np.array([m.values[i] for i in rows])[np.argmax(t)], 0.02, 0.95)
        th = np.stack([np.log((1 - r) ** 2 / (2 * r)), np.zeros_like(r)])  # (2, B): log K, log S
        f = lambda th: np.log(over(*km_layer(np.exp(th[0]), np.exp(th[1]), t[:, None]), paper) + 0.01) - Y  # noqa: E731
        mu = 1e-2
        for _ in range(200):
            r0 = f(th)
            J = np.stack([(f(th + h) - r0) / 1e-6 for h in 1e-6 * np.eye(2)[:, :, None]], -1)  # (n, B, 2)
            H = np.einsum("nbi,nbj->bij", J, J) + 1e-6 * np.eye(2)
            g = np.einsum("nbi,nb->bi", J, r0)
            d = -np.linalg.solve(H + mu * np.eye(2), g[..., None])[..., 0].T
            new = np.clip(th + d, -12, 12)
            if np.sum(f(new) ** 2) < np.sum(r0**2):
                th, mu = new, mu / 3
            else:
                mu *= 4
        out[name] = (np.exp(th[0]), np.exp(th[1]))
    return m.wavelengths, out, paper


def maker(rng, n_paints: int, scatter: float = 0.0):
    """The other maker's paints on WL: dict name -> (K, S, thickness, k1, k2); and the two grounds. `scatter`
    shifts every made paint's log S (negative: a maker of transparent inks; positive: of opaque gouache)."""
    wl, base, paper = ntu_paints()
    names = list(base)
    paints = {}
    x = (WL - 400) / 380
    for i in range(n_paints - 3):
        K0, S0 = base[names[i % len(names)]]
        shift = rng.uniform(-25, 25)
        K = np.exp(np.interp(WL - shift, wl, np.log(K0)) + rng.normal(0, 0.3))
        S = np.exp(np.interp(WL - shift, wl, np.log(S0)) + rng.normal(scatter, 1.0) + rng.normal(0, 0.3) * (x - 0.5))
        paints[f"M{i + 1}"] = [np.clip(K, 1e-4, 1e3), np.clip(S, 1e-4, 1e3), np.exp(rng.uniform(np.log(0.6), np.log(2.5)))]
    paints["white1"] = [0.03 + 0.1 * np.exp(-(((WL - 400) / 30) ** 2)), np.full(len(WL), 6.0) * (1.2 - 0.4 * x), 1.0]
    paints["white2"] = [np.full(len(WL), 0.05), np.full(len(WL), 2.5), 1.0]
    paints["black"] = [np.full(len(WL), 12.0) * (1 + 0.1 * x), np.full(len(WL), 0.3), 1.0]
    for p in paints.values():
        p += [rng.uniform(0.0, 0.02), rng.uniform(0.35, 0.6)]
    white = np.interp(WL, wl, paper)
    cream = white * (0.84 + 0.1 * x) * (1 - 0.12 * np.exp(-(((WL - 420) / 45) ** 2)))
    return paints, {"white": white, "cream": cream}


def mixed(paints, names, frac, ground, inter, rng):
    """A mixture's measured reflectance: fractions `frac` of `names` (sum 1) brushed as one layer at the
    fraction-weighted thickness, with the pairs' departures from Duncan (`inter`) and measurement noise."""
    K = sum(c * paints[n][0] for n, c in zip(names, frac))
    S = sum(c * paints[n][1] for n, c in zip(names, frac))
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            a, s = inter[tuple(sorted((names[i], names[j])))]
            K, S = K * np.exp(4 * frac[i] * frac[j] * a), S * np.exp(4 * frac[i] * frac[j] * s)
    t, k1, k2 = (sum(c * paints[n][k] for n, c in zip(names, frac)) for k in (2, 3, 4))
    R = measured(K, S, t, ground, k1, k2)
    R = R * (1 + rng.normal(0, 0.01)) * (1 + rng.normal(0, 0.005, len(R))) + rng.normal(0, 0.002, len(R))
    return np.clip(R, 1e-3, 1.0)


def stacked(paints, bottom: str, top: str, ground, rng, uneven=0.25):
    """A glaze stack's measured reflectance: `top` brushed over dry `bottom`, each a layer of its own uneven
    thickness (independent log-normal, Gauss-Hermite average), over `ground`, seen through `top`'s surface."""
    x, w = np.polynomial.hermite_e.hermegauss(5)
    w = w / w.sum()
    (Ka, Sa, ta, _, _), (Kb, Sb, tb, k1, k2) = paints[bottom], paints[top]
    g_in = ground / (1 - k2 + k2 * ground)
    R = 0.0
    for xa, wa in zip(x, w):
        lower = over(*km_layer(Ka, Sa, ta * np.exp(uneven * xa - 0.5 * uneven**2)), g_in)
        for xb, wb in zip(x, w):
            R = R + wa * wb * over(*km_layer(Kb, Sb, tb * np.exp(uneven * xb - 0.5 * uneven**2)), lower)
    R = k1 + (1 - k1) * (1 - k2) * R / (1 - k2 * R)
    R = R * (1 + rng.normal(0, 0.01)) * (1 + rng.normal(0, 0.005, len(R))) + rng.normal(0, 0.002, len(R))
    return np.clip(R, 1e-3, 1.0)


def generated_case(seed: int, n_paints: int, scatter: float = 0.0):
    """The table (list of rows) and the held-out queries of one seed (module docstring)."""
    rng = np.random.default_rng(seed)
    paints, grounds = maker(rng, n_paints, scatter)
    names = list(paints)
    inter = {}
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            inter[tuple(sorted((a, b)))] = (rng.normal(0, 0.15), rng.normal(0, 0.3))
    table = [(g, "0", g, v) for g, v in grounds.items()]
    for n in names:
        for g, v in grounds.items():
            table.append((n, "1", g, mixed(paints, [n], [1.0], v, inter, rng)))
    held, seen = [], set()
    while len(held) < 44:
        k = 2 if len(held) < 30 else 3
        pick = tuple(sorted(rng.choice(len(names), k, replace=False)))
        if pick in seen:
            continue
        seen.add(pick)
        w = rng.choice([1, 2, 3], k)
        frac = w / w.sum()
        held.append(([names[i] for i in pick], frac))
    queries = {g: [(p, f, mixed(paints, p, f, v, inter, rng)) for p, f in held] for g, v in grounds.items()}
    srng = np.random.default_rng(seed + 1000)  # the stacks' own draws: the table and mixtures stay as they were
    pairs = set()
    while len(pairs) < 22:
        a, b = (names[i] for i in srng.choice(len(names), 2, replace=False))
        pairs.add((a, b))
    stacks = {g: [((a, b), stacked(paints, a, b, v, srng)) for a, b in sorted(pairs)] for g, v in grounds.items()}
    return table, queries, stacks


# ---------------------------------------------------------------- the predictions that need no fit


def geometric_mean(single, pigments, frac):
    return np.exp(sum(c * np.log(np.maximum(single[p], 1e-4)) for p, c in zip(pigments, frac)))


def one_constant(single, pigments, frac):
    ks = sum(c * (1 - np.clip(single[p], 1e-4, 0.999)) ** 2 / (2 * np.clip(single[p], 1e-4, 0.999))
             for p, c in zip(pigments, frac))  # fmt: skip
    return 1 + ks - np.sqrt(ks * ks + 2 * ks)


def mixbox_lab(single, queries, obs):
    try:
        import mixbox  # benchmark-only peer (pymixbox, CC BY-NC)
    except ImportError:
        return None
    out = []
    for p, f in queries:
        rgb = [np.clip(np.asarray(colorimetry.srgb_encode(obs.linear_srgb(single[n]))), 0, 1) * 255 for n in p]
        z = sum(c * np.asarray(mixbox.rgb_to_latent(tuple(float(v) for v in x))) for x, c in zip(rgb, f))
        out.append(np.asarray(colorimetry.srgb_to_lab(np.asarray(mixbox.latent_to_rgb(list(z)), float) / 255)))
    return np.array(out)


def _write(path: Path, wl, rows) -> None:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pigment", "amount", "ground", *(f"{v:g}" for v in wl)])
        w.writerows([(p, a, g, *(f"{x:.6f}" for x in v)) for p, a, g, v in rows])


def score(table_rows, wl, queries: dict, amount_of, label: str, stacks: dict | None = None) -> None:
    """Fit the table, predict each ground's queries (and `stacks`: ground -> [((bottom, top), R)]), print one line
    per method and ground."""
    with tempfile.TemporaryDirectory() as tmp:
        _write(Path(tmp, "t.csv"), wl, table_rows)
        m = measurements.read_measurements(Path(tmp, "t.csv"))
    t0, c0 = time.perf_counter(), time.process_time()
    fit = fit_mixtures(m)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    obs = spectral.observation(wl)
    gam = np.asarray(fit.library.palette.law.gamma)
    S = np.asarray(fit.library.palette.S)
    print(f"\n{label}: fit of {len(m)} rows, {len(m.names)} paints, {len(wl)} bands: {wall:.1f} s ({cpu:.1f} s CPU), "
          f"converged {fit.converged}, mean dE2000 of its rows {fit.summary()['mean_de2000']:.2f}; exponents "
          f"{gam.min():.3g}-{gam.max():.3g}; smallest mean S {S.mean(axis=1).min():.3g}\n", flush=True)  # fmt: skip
    print("| ground | held-out rows | diffwash | held by its 90% regions (median radius) | model error holding 90% "
          "| one-constant K/S | geometric mean | Mixbox |\n|---|---|---|---|---|---|---|---|")
    for g, qs in queries.items():
        single = {p: v for p, a, gg, v in table_rows if gg == g and a != "0"}
        truth = np.asarray(obs.lab(np.array([v for _, _, v in qs])))
        rows = (["+".join(p) for p, _, _ in qs], [amount_of(f) for _, f, _ in qs], [g] * len(qs))
        pred = fit.library.predict(*rows)
        held, s90 = _coverage(fit.library, rows, truth, pred)
        labs = {"diffwash": pred.lab}
        for name, fn in (("one", one_constant), ("geo", geometric_mean)):
            labs[name] = np.asarray(obs.lab(np.array([fn(single, p, f) for p, f, _ in qs])))
        mb = mixbox_lab(single, [(p, f) for p, f, _ in qs], obs)
        de = {k: float(np.mean(np.asarray(colorimetry.delta_e_2000(v, truth)))) for k, v in labs.items()}
        if mb is not None:
            de["mixbox"] = float(np.mean(np.asarray(colorimetry.delta_e_2000(mb, truth))))
        print(f"| {g} | {len(qs)} | {de['diffwash']:.2f} | {held} | {s90:.2f} | {de['one']:.2f} | {de['geo']:.2f} | "
              f"{de.get('mixbox', float('nan')):.2f} |", flush=True)  # fmt: skip
    if stacks:
        print("\n| ground | held-out glaze stacks | diffwash | held by its 90% regions (median radius) | model error "
              "holding 90% | the top paint's layer alone |\n|---|---|---|---|---|---|")  # fmt: skip
        for g, qs in stacks.items():
            single = {p: v for p, a, gg, v in table_rows if gg == g and a != "0"}
            truth = np.asarray(obs.lab(np.array([v for _, v in qs])))
            rows = (["/".join(ab) for ab, _ in qs], ["1/1"] * len(qs), [g] * len(qs))
            pred = fit.library.predict(*rows)
            held, s90 = _coverage(fit.library, rows, truth, pred)
            top = np.asarray(obs.lab(np.array([single[b] for (_, b), _ in qs])))
            de, de_top = (float(np.mean(np.asarray(colorimetry.delta_e_2000(x, truth)))) for x in (pred.lab, top))
            print(f"| {g} | {len(qs)} | {de:.2f} | {held} | {s90:.2f} | {de_top:.2f} |", flush=True)


def _coverage(lib, rows, truth, pred) -> tuple[str, float]:
    """The share of held-out rows inside their 90% regions (and the regions' median radius), and the model error of
    the rows' kind (CIELAB units per axis) that would make them hold 90% (`_posterior.calibrate_scale`): what a
    prior for a table that mixes nothing should be (`_priors.UNMIXED_PRIOR`)."""
    q = library._as_queries(*rows)
    A, G = lib.layer_amounts(q.pigments, q.amounts, q.layers), lib.ground_matrix(q.ground)
    spread = _regions.lab_draws(lib.posterior, lib.palette, A, G, lib.k2, lib.observation.lab)
    s90 = _posterior.calibrate_scale(truth, pred.lab, spread)
    if pred.de2000_90 is None or not np.isfinite(pred.de2000_90).any():
        return "no regions", s90
    de = np.asarray(colorimetry.delta_e_2000(pred.lab, truth))
    ok = np.isfinite(pred.de2000_90)
    return f"{100 * np.mean(de[ok] <= pred.de2000_90[ok]):.1f}% ({np.median(pred.de2000_90[ok]):.1f})", s90


def generated(seeds, n_paints: int, scatter: float = 0.0) -> None:
    for seed in seeds:
        table, queries, stacks = generated_case(seed, n_paints, scatter)
        label = f"Generated, seed {seed}" + (f", log S shifted by {scatter:+g}" if scatter else "")
        score(table, WL, queries, lambda f: "+".join(f"{x:.4f}" for x in f), label, stacks)


def ntu() -> None:
    m = measurements.read_measurements(NTU)
    rows = [("paper", "0", "paper", m.grounds["paper"])]
    rows += [(p[0], "0.06", "paper", v) for p, a, v in zip(m.pigments, m.amounts, m.values)
             if len(p) == 1 and abs(a[0] - 0.06) < 1e-9]  # fmt: skip
    for total in (0.06, 0.03, 0.12):
        qs = [(list(p), np.asarray(a) / sum(a), v) for p, a, v in zip(m.pigments, m.amounts, m.values)
              if len(set(p)) == 2 and abs(sum(a) - total) < 1e-9]  # fmt: skip
        score(rows, m.wavelengths, {"paper": qs}, lambda f, t=total: "+".join(f"{x * t:.4f}" for x in f),
              f"NTU, one amount (0.06 mL) per paint; mixtures at {total} mL")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--paints", type=int, default=40)
    ap.add_argument("--only", default="generated,ntu")
    ap.add_argument("--scatter", type=float, default=0.0,
                    help="shift of the generated paints' log S: -2 a maker of transparent inks, +1 of gouache")
    args = ap.parse_args()
    only = args.only.split(",")
    if "generated" in only:
        generated([int(s) for s in args.seeds.split(",")], args.paints, args.scatter)
    if "ntu" in only:
        ntu()


if __name__ == "__main__":
    main()
