"""Start-up: how long the command line and `import diffwash` take, each in a fresh process.

    python benchmarks/bench_startup.py [--repeats 7] [--importtime 15] [--tree PATH]

Prints Markdown tables:

1. The median (min, max) wall time of `diffwash --version`, `diffwash --help`, `diffwash render --help`,
   `diffwash pigments` and `python -c "import diffwash"`, each run `--repeats` times in a new process, the
   commands interleaved round by round so that load from other work on a shared machine hits all alike.
   Targets (issue 22): `--version` and `--help` <= 0.5 s (goal 0.2 s), `pigments` <= 1.5 s (goal 0.8 s).
2. Which heavy dependencies each one leaves in `sys.modules`.
3. The `--importtime` slowest imports (cumulative) of `python -X importtime -m diffwash pigments`.

`--tree PATH` times another checkout (e.g. one before this change) in the same rounds, beside this one.
The persistent compilation cache is left as it is: none of these commands compiles anything.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Dependencies that a command which neither renders nor fits should not load.
HEAVY = ("jax", "colour", "matplotlib", "moderngl", "OpenEXR", "scipy", "trimesh", "PIL.Image", "optimistix", "equinox")

#: (label, python arguments): every command runs as `python -m diffwash ...`, the console script's work.
COMMANDS = (
    ("diffwash --version", ["-m", "diffwash", "--version"]),
    ("diffwash --help", ["-m", "diffwash", "--help"]),
    ("diffwash render --help", ["-m", "diffwash", "render", "--help"]),
    ("diffwash pigments", ["-m", "diffwash", "pigments"]),
    ('python -c "import diffwash"', ["-c", "import diffwash"]),
)
TARGETS = {"diffwash --version": "<= 0.5 (goal 0.2)", "diffwash --help": "<= 0.5 (goal 0.2)",
           "diffwash pigments": "<= 1.5 (goal 0.8)"}  # fmt: skip


def _env(tree: Path) -> dict[str, str]:
    """`tree` first on the path (each command also runs in `tree`: `-m` and `-c` put the working folder first)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(tree), *filter(None, [env.get("PYTHONPATH")])])
    return env


def _time(args: list[str], tree: Path) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, *args], env=_env(tree), cwd=tree, stdout=subprocess.DEVNULL, check=True)
    return time.perf_counter() - start


def wall_times(repeats: int, trees: dict[str, Path]) -> None:
    times = {(label, t): [] for label, _ in COMMANDS for t in trees}
    for _ in range(repeats):
        for label, args in COMMANDS:
            for t, tree in trees.items():
                times[label, t].append(_time(args, tree))
    print(f"| command | tree | wall time, s: median (min, max) of {repeats} | target, s |")
    print("| --- | --- | --- | --- |")
    for (label, t), ts in times.items():
        print(f"| `{label}` | {t} | {statistics.median(ts):.3f} ({min(ts):.3f}, {max(ts):.3f}) | {TARGETS.get(label, '')} |")


_PROBE = """
import runpy, sys
if sys.argv[1] == "-c":
    exec(sys.argv[2])
else:
    sys.argv = ["diffwash", *sys.argv[3:]]
    try:
        runpy.run_module("diffwash", run_name="__main__")
    except SystemExit:
        pass
print("LOADED", *[m for m in {heavy!r} if m in sys.modules], file=sys.stderr)
"""


def loaded_modules(trees: dict[str, Path]) -> None:
    print("\n| command | tree | heavy modules loaded |")
    print("| --- | --- | --- |")
    for label, args in COMMANDS:
        for t, tree in trees.items():
            run = subprocess.run([sys.executable, "-c", _PROBE.format(heavy=HEAVY), *args], env=_env(tree), cwd=tree,
                                 capture_output=True, text=True, check=True)  # fmt: skip
            loaded = [line for line in run.stderr.splitlines() if line.startswith("LOADED")][-1].split()[1:]
            print(f"| `{label}` | {t} | {', '.join(loaded) or 'none'} |")


def import_offenders(top: int, tree: Path) -> None:
    run = subprocess.run([sys.executable, "-X", "importtime", "-m", "diffwash", "pigments"], env=_env(tree), cwd=tree,
                         capture_output=True, text=True, check=True)  # fmt: skip
    rows = []
    for line in run.stderr.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        own, cumulative, name = line.removeprefix("import time:").split("|")
        rows.append((int(cumulative), int(own), name.strip()))
    rows.sort(reverse=True)
    print(f"\n`python -X importtime -m diffwash pigments` ({tree}), the {top} slowest imports (cumulative):\n")
    print("| module | cumulative, ms | self, ms |")
    print("| --- | --- | --- |")
    for cum, own, name in rows[:top]:
        print(f"| `{name}` | {cum / 1000:.1f} | {own / 1000:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--importtime", type=int, default=15, metavar="N")
    ap.add_argument("--tree", type=Path, help="another checkout to time beside this one")
    a = ap.parse_args()
    trees = {"this": ROOT, **({"other": a.tree.resolve()} if a.tree else {})}
    wall_times(a.repeats, trees)
    loaded_modules(trees)
    for tree in trees.values():
        if a.importtime:
            import_offenders(a.importtime, tree)


if __name__ == "__main__":
    main()
