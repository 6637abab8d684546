"""The real-time path: LUT bake time, and frames per second of the LUT shader against a shader that
evaluates Kubelka-Munk per fragment (the seed's claim that the LUT is faster), measured in one run.

    python benchmarks/bench_lut.py [--scene data/scenes/knot.json] [--size 1024] [--seconds 3]

Prints Markdown tables. Bake: compile time (first call, includes JAX tracing and XLA compilation)
and warm time (median of repeats), float32 on the CPU. Shaders: the exported glsl330 shaders drawn
offscreen by moderngl at SIZE^2 on the scene's mesh, 8-bit sRGB output, depth test and back-face
culling as in the preview; the LUT and the KM shader alternate in ROUNDS rounds (SECONDS in all per
shader, glFinish every 5 frames); the table gives the median fps and the median per-round ratio.
Without a GPU this is Mesa's llvmpipe (LP_NUM_THREADS threads, default: all cores). Last, the
preview's agreement with `diffwash render` on the same scene.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import diffwash  # noqa: E402
from diffwash import lut, preview  # noqa: E402


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def bench_bake(params, size: int, repeats: int) -> dict:
    t0 = time.perf_counter()
    lut.bake(params, size)
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        lut.bake(params, size)
        times.append(time.perf_counter() - t0)
    warm = statistics.median(times)
    return {"warm": warm, "compile": max(first - warm, 0.0), "rss": peak_rss_mb()}


def _fps(ctx, p, fbo, seconds: float) -> float:
    frames, t0 = 0, time.perf_counter()
    while True:
        p.draw(fbo)
        frames += 1
        if frames % 5 == 0:
            ctx.finish()
            elapsed = time.perf_counter() - t0
            if elapsed >= seconds:
                return frames / elapsed


def bench_shaders(ctx, scene, shading: str, size: int, seconds: float, rounds: int) -> tuple[float, float, float]:
    """Median fps of the LUT and the KM shader and the median of their per-round ratio.

    The two alternate in `rounds` rounds of `seconds / rounds` each, so that a load change on a
    shared machine hits both alike.
    """
    progs = {c: preview.Preview(ctx, scene, shading=shading, colour=c) for c in ("lut", "km")}
    fbo = progs["lut"].framebuffer(size, size)
    ctx.viewport = (0, 0, size, size)
    for p in progs.values():  # warm up: shader compilation in the driver, texture upload
        for _ in range(3):
            p.draw(fbo)
    ctx.finish()
    fps = {"lut": [], "km": []}
    for _ in range(rounds):
        for c, p in progs.items():
            fps[c].append(_fps(ctx, p, fbo, seconds / rounds))
    for p in progs.values():
        p.release()
    ratios = [a / b for a, b in zip(fps["lut"], fps["km"])]
    return statistics.median(fps["lut"]), statistics.median(fps["km"]), statistics.median(ratios)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "data" / "scenes" / "knot.json"))
    ap.add_argument("--size", type=int, default=1024, help="framebuffer side for the shader timings")
    ap.add_argument("--seconds", type=float, default=5.0, help="drawing time per shader")
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds of LUT and KM drawing")
    ap.add_argument("--repeats", type=int, default=5, help="warm repeats per bake size")
    args = ap.parse_args(argv)

    scene = diffwash.load_scene(args.scene)
    n_tri = int(np.asarray(scene.mesh.faces).shape[0])
    print(f"# diffwash {diffwash.__version__}: LUT bake and real-time shaders")
    print(f"scene {Path(args.scene).name}: {n_tri} triangles; {os.cpu_count()} CPU cores visible\n")

    print("| bake | warm (s) | compile (s) | peak RSS (MB) |")
    print("| --- | ---: | ---: | ---: |")
    for size in (256, 1024):
        r = bench_bake(scene.params, size, args.repeats)
        print(f"| {size}x{size} colour LUT | {r['warm']:.3f} | {r['compile']:.3f} | {r['rss']:.0f} |")

    ctx = preview.create_context()
    print(f"\nOpenGL: {ctx.info['GL_RENDERER']} ({ctx.info['GL_VERSION']}), LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'default')}")
    print(f"{args.size}x{args.size} framebuffer, {n_tri} triangles, >= {args.seconds:g} s per shader\n")
    print("| thickness | LUT shader (fps) | KM per fragment (fps) | LUT / KM |")
    print("| --- | ---: | ---: | ---: |")
    for shading in ("per-pixel", "per-vertex"):
        fps_lut, fps_km, ratio = bench_shaders(ctx, scene, shading, args.size, args.seconds, args.rounds)
        print(f"| {shading} | {fps_lut:.1f} | {fps_km:.1f} | {ratio:.2f}x |")
    print("\nAgreement with `diffwash render` (8-bit sRGB, 256x256 png16 LUT, the scene's image size):\n")
    print("| thickness | OpenGL preview PSNR (dB) | pixels > 1 level apart |")
    print("| --- | ---: | ---: |")
    for shading in ("per-pixel", "per-vertex"):
        s = diffwash.load_scene(args.scene, shading=shading)
        ref = np.round(diffwash.colorimetry.to_display(np.asarray(diffwash.render(s))) * 255)
        frame = np.round(preview.render(s, lut=lut.load_encoded(lut.bake(s, 256), "png16"), ctx=ctx) * 255)
        mse = np.mean(((frame - ref) / 255) ** 2)
        far = int(np.sum(np.abs(frame - ref).max(-1) > 1))
        print(f"| {shading} | {10 * np.log10(1 / mse):.1f} | {far} of {frame.shape[0] * frame.shape[1]} |")
    ctx.release()
    return 0


if __name__ == "__main__":
    sys.exit(main())
