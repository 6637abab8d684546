"""Convert the Kimera acrylic measurements of miciwan/PaintMixing to diffwash's measurement tables.

Usage, from the repository root (SOURCE holds the upstream `masstone.json` and `mix1.json`):

    python data/kimera-paintmixing/convert.py SOURCE [-o data/kimera-paintmixing]

Writes `kimera-all.csv` (every row), `kimera-train.csv` (what a fit may see) and
`kimera-heldout.csv` (the rows it may not), in the format of `diffwash.measurements`.
What the conversion does and why is in this folder's README.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

#: Band centres written, nm: the instrument's trustworthy range (the author: weak below 410 nm and
#: above 680 nm), on the 10 nm grid ASTM E308 tabulates.
BANDS = np.arange(390, 711, 10)

#: The black primer under every patch was never measured; the opaque black paint's own masstone
#: stands in for it (see the README).
GROUND = "primer"

#: The split, fixed before any fit: the tints with white of every third chromatic paint in the
#: upstream file's order (3rd, 6th, 9th, 12th) are held out; their masstones stay in training.
HELD_OUT_TINTS = ("yellow-oxide", "red-oxide", "blue-red-shade", "black")


def _name(upstream: str) -> str:
    return "-".join(upstream.split())


def _bands(wavelengths: np.ndarray, percent: np.ndarray) -> np.ndarray:
    """Mean of the samples within +-5 nm of each band centre, as reflectance 0..1."""
    out = []
    for c in BANDS:
        near = np.abs(wavelengths - c) <= 5.0
        if not near.any():
            raise SystemExit(f"no upstream sample within 5 nm of {c} nm")
        out.append(percent[near].mean() / 100.0)
    return np.asarray(out)


def _load(path: Path) -> tuple[np.ndarray, list[dict]]:
    entries = json.loads(path.read_text())
    wl = np.asarray(next(e for e in entries if e.get("type") == "wavelengths")["values"], float)
    return wl, [e for e in entries if e.get("type") in ("masstone", "mix")]


def rows(source: Path) -> list[tuple[str, str, np.ndarray]]:
    """(pigment, amount, reflectance) per sample, its three repeat readings averaged."""
    groups: dict[tuple[str, str], list[np.ndarray]] = {}
    for fname in ("masstone.json", "mix1.json"):
        wl, entries = _load(source / fname)
        for e in entries:
            if e["type"] == "masstone":
                key = (_name(e["name"]), "1")
            else:
                comp = e["components"]
                total = sum(comp.values())
                names = sorted(comp, key=lambda n: n == "white")  # the coloured paint first, white second
                key = ("+".join(_name(n) for n in names), "+".join(f"{comp[n] / total:.4f}" for n in names))
            groups.setdefault(key, []).append(_bands(wl, np.asarray(e["reflectance"], float)))
    return [(p, a, np.mean(v, axis=0)) for (p, a), v in groups.items()]


def _write(path: Path, table: list[tuple[str, str, np.ndarray]], ground: np.ndarray) -> None:
    head = "pigment,amount,ground," + ",".join(str(b) for b in BANDS)
    lines = [head, f"{GROUND},0,{GROUND}," + ",".join(f"{x:.5f}" for x in ground)]
    lines += [f"{p},{a},{GROUND}," + ",".join(f"{x:.5f}" for x in v) for p, a, v in table]
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("source", type=Path, help="folder with the upstream masstone.json and mix1.json")
    ap.add_argument("-o", "--out", type=Path, default=Path(__file__).parent)
    args = ap.parse_args()
    table = rows(args.source)
    ground = next(v for p, a, v in table if p == "black" and a == "1")
    held = [r for r in table if "+" in r[0] and r[0].split("+")[0] in HELD_OUT_TINTS]
    train = [r for r in table if r not in held]
    args.out.mkdir(parents=True, exist_ok=True)
    _write(args.out / "kimera-all.csv", table, ground)
    _write(args.out / "kimera-train.csv", train, ground)
    _write(args.out / "kimera-heldout.csv", held, ground)
    print(f"{len(table)} samples: {len(train)} to train, {len(held)} held out -> {args.out}")


if __name__ == "__main__":
    main()
