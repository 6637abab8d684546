"""The JAX renderer's speed: forward, forward + gradient, compile time, memory, rasterization cost,
and peers (OpenGL on Mesa llvmpipe, Mitsuba 3 llvm_ad_rgb) measured in the same run.

    python benchmarks/bench_render.py [--scene data/scenes/knot.json] [--repeats 30] [--quick]

Prints Markdown tables (the numbers issue 3 asks for). Each part runs in a fresh Python process, so
compile times are cold (persistent compilation cache off) and peak memory belongs to that part
alone. Timings are medians of warm repeats (min in brackets) in float32 on the CPU; the peers and
diffwash alternate in rounds within one process, so that a load change on a shared machine hits
all alike, and ratios are medians of per-round ratios. Mitsuba needs `pip install mitsuba` and
Debian's libllvm19 (benchmarks/setup.sh); without them its rows say why they are missing.
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
os.environ.setdefault("DIFFWASH_CACHE_DIR", "off")


def rss_mb() -> float:
    """Peak resident memory of this process so far, MiB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def current_rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def timed(fn, repeats: int) -> dict:
    """Median and min wall time of `fn()` over `repeats` calls (it must block until done)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return {"median": statistics.median(times), "min": min(times)}


# ---------------------------------------------------------------------------
# Workers (each runs in its own process and prints one JSON object).


def gradient_problem(scene):
    """The timed gradient: `jit(value_and_grad)` of an image MSE against a dimmed render, w.r.t. all shading params."""
    import jax
    import jax.numpy as jnp

    import diffwash

    target = diffwash.render(scene) * 0.95

    @jax.jit
    @jax.value_and_grad
    def loss_and_grad(params):
        return jnp.mean((diffwash.render(scene, params) - target) ** 2)

    return loss_and_grad


def worker_jax(args) -> dict:
    import jax
    import jax.numpy as jnp

    import diffwash

    out = {}
    scene = diffwash.load_scene(args.scene)
    base = current_rss_mb()
    out["triangles"] = len(scene.mesh.faces)
    out["size"] = f"{scene.width}x{scene.height}"

    t0 = time.perf_counter()
    vis = diffwash.rasterize(scene)
    out["compile_rasterize"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    jax.block_until_ready(diffwash.render(scene, visibility=vis))
    out["compile_render"] = time.perf_counter() - t0
    out["covered"] = int(jnp.sum(vis.tri_id >= 0))

    out["rasterize"] = timed(lambda: diffwash.rasterize(scene), args.repeats)
    out["forward_cached"] = timed(lambda: jax.block_until_ready(diffwash.render(scene)), args.repeats)
    out["forward_visibility_given"] = timed(
        lambda: jax.block_until_ready(diffwash.render(scene, visibility=vis)), args.repeats
    )
    out["forward_with_raster"] = timed(
        lambda: jax.block_until_ready(diffwash.render(scene, visibility=diffwash.rasterize(scene))), args.repeats
    )
    out["rss_forward"] = current_rss_mb() - base

    loss_and_grad = gradient_problem(scene)
    t0 = time.perf_counter()
    jax.block_until_ready(loss_and_grad(scene.params))
    out["compile_grad"] = time.perf_counter() - t0
    out["forward_grad"] = timed(lambda: jax.block_until_ready(loss_and_grad(scene.params)), args.repeats)
    n_params = sum(int(jnp.size(x)) for x in jax.tree_util.tree_leaves(scene.params))
    out["n_params"] = n_params

    import dataclasses

    pv = dataclasses.replace(scene, shading="per-vertex")
    t0 = time.perf_counter()
    jax.block_until_ready(diffwash.render(pv, visibility=vis))
    out["compile_per_vertex"] = time.perf_counter() - t0
    out["forward_per_vertex"] = timed(lambda: jax.block_until_ready(diffwash.render(pv, visibility=vis)), args.repeats)

    t0 = time.perf_counter()
    vis_aa = diffwash.rasterize(scene, antialias=True)
    jax.block_until_ready(diffwash.render(scene, visibility=vis_aa, antialias=True))
    out["compile_antialias"] = time.perf_counter() - t0
    out["prepare_antialias"] = timed(lambda: diffwash.rasterize(scene, antialias=True), max(3, args.repeats // 3))
    out["forward_antialias"] = timed(
        lambda: jax.block_until_ready(diffwash.render(scene, visibility=vis_aa, antialias=True)), args.repeats
    )
    out["silhouette_items"] = int(jnp.sum(vis_aa.silhouettes.a < scene.width * scene.height))
    out["rss_peak"] = rss_mb()
    out["rss_base"] = base
    return out


def worker_grad(args) -> dict:
    """Forward and forward + gradient only (run again under different XLA flags)."""
    import jax

    import diffwash

    scene = diffwash.load_scene(args.scene)
    vis = diffwash.rasterize(scene)
    loss_and_grad = gradient_problem(scene)
    jax.block_until_ready(loss_and_grad(scene.params))
    jax.block_until_ready(diffwash.render(scene, visibility=vis))
    return {
        "forward_visibility_given": timed(
            lambda: jax.block_until_ready(diffwash.render(scene, visibility=vis)), args.repeats
        ),
        "forward_grad": timed(lambda: jax.block_until_ready(loss_and_grad(scene.params)), args.repeats),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }


#: XLA CPU option that helps the gradient here (YNNPACK reduction fusions off); experimental,
#: so measured as an extra row rather than set by the library.
NO_YNN = "--xla_cpu_experimental_ynn_fusion_type="


def worker_raster_table(args) -> dict:
    import dataclasses

    import numpy as np

    import diffwash
    from diffwash._meshes import torus_knot
    from diffwash._scene import Mesh

    base = diffwash.load_scene(args.scene)
    rows = {}
    for label, (seg, sides) in {"1k": (50, 10), "10k": (250, 20), "100k": (1000, 50)}.items():
        v, f, n = torus_knot(seg, sides)
        mesh = Mesh(vertices=v, faces=f.astype(np.int32), normals=n, closed=True)
        for size in args.raster_sizes:
            scene = dataclasses.replace(base, mesh=mesh, width=size, height=size)
            diffwash.rasterize(scene)  # compile
            t = timed(lambda: diffwash.rasterize(scene), args.repeats)
            rows[f"{label}/{size}"] = {**t, "triangles": len(f)}
    return rows


def _gl_setup(scene):
    """A moderngl (EGL, llvmpipe) context drawing the scene with the tests' independent GLSL model."""
    sys.path.insert(0, str(ROOT / "tests"))
    import gl_reference as ref  # the tests' OpenGL reference: camera, model, draw (imports no conftest)

    ctx, prog = ref.create()
    return ctx, prog, ref


def worker_compare(args) -> dict:
    """diffwash, OpenGL and Mitsuba alternating in rounds in one process."""
    import jax
    import numpy as np

    import diffwash

    scene = diffwash.load_scene(args.scene)
    out = {"notes": {}}
    vis = diffwash.rasterize(scene)
    loss_and_grad = gradient_problem(scene)

    tasks = {
        "diffwash forward": lambda: jax.block_until_ready(diffwash.render(scene, visibility=vis)),
        "diffwash forward + rasterize": lambda: jax.block_until_ready(
            diffwash.render(scene, visibility=diffwash.rasterize(scene))
        ),
        "diffwash forward + gradient": lambda: jax.block_until_ready(loss_and_grad(scene.params)),
    }

    # OpenGL: the same mesh, camera, model (per-pixel GLSL), size; draw + glFinish + readback.
    try:
        ctx, prog, ref = _gl_setup(scene)
        ref.gl_render((ctx, prog), scene)  # warm up (shader compile, buffers)
        tasks["OpenGL llvmpipe render + readback"] = lambda: ref.gl_render((ctx, prog), scene)
        out["notes"]["opengl"] = ctx.info["GL_RENDERER"]
    except Exception as e:  # noqa: BLE001 - report, do not crash the benchmark
        out["notes"]["opengl"] = f"not run: {type(e).__name__}: {e}".splitlines()[0]

    # Mitsuba 3: direct integrator, 1 spp, same mesh/camera/size; diffuse BSDF.
    try:
        mts = _mitsuba_tasks(scene, args)
        tasks.update(mts["tasks"])
        out["notes"]["mitsuba"] = mts["note"]
        out["mitsuba_first_forward"] = mts["first_forward"]
        out["mitsuba_first_gradient"] = mts["first_gradient"]
    except Exception as e:  # noqa: BLE001
        out["notes"]["mitsuba"] = f"not run: {type(e).__name__}: {e}".splitlines()[0]

    for fn in tasks.values():  # warm up everything
        fn()
    times = {k: [] for k in tasks}
    per_round = max(1, args.repeats // args.rounds)
    for _ in range(args.rounds):
        for k, fn in tasks.items():
            times[k].append(timed(fn, per_round)["median"])
    out["times"] = {k: {"median": statistics.median(v), "min": min(v)} for k, v in times.items()}
    ratios = {}
    for ours, peer in (
        ("diffwash forward", "OpenGL llvmpipe render + readback"),
        ("diffwash forward + rasterize", "OpenGL llvmpipe render + readback"),
        ("diffwash forward", "Mitsuba direct 1 spp forward"),
        ("diffwash forward + rasterize", "Mitsuba direct 1 spp forward"),
        ("diffwash forward + gradient", "Mitsuba direct 1 spp forward + gradient"),
    ):
        if ours in times and peer in times:
            ratios[f"{ours} / {peer}"] = statistics.median(a / b for a, b in zip(times[ours], times[peer]))
    out["ratios"] = ratios
    out["rss_peak"] = rss_mb()
    del np
    return out


def _mitsuba_tasks(scene, args) -> dict:
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    mi.set_variant("llvm_ad_rgb")
    cam = scene.camera
    src = json.loads(Path(args.scene).read_text())
    mesh_path = str((Path(args.scene).parent / src["mesh"]).resolve())
    light = np.asarray(scene.params.light, float)
    light = light / np.linalg.norm(light)
    m = mi.load_dict(
        {
            "type": "scene",
            "integrator": {"type": "direct"},
            "sensor": {
                "type": "perspective",
                "fov": float(cam.fov_y),
                "fov_axis": "y",
                "near_clip": float(cam.near),
                "far_clip": float(cam.far),
                "to_world": mi.ScalarTransform4f().look_at(
                    origin=np.asarray(cam.eye, float).tolist(),
                    target=np.asarray(cam.target, float).tolist(),
                    up=np.asarray(cam.up, float).tolist(),
                ),
                "film": {
                    "type": "hdrfilm",
                    "width": scene.width,
                    "height": scene.height,
                    "rfilter": {"type": "box"},
                    "pixel_format": "rgb",
                },
                "sampler": {"type": "independent", "sample_count": 1},
            },
            "knot": {
                "type": "ply",
                "filename": mesh_path,
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.3, 0.5]}},
            },
            "sun": {"type": "directional", "direction": (-light).tolist(), "irradiance": {"type": "rgb", "value": 3.0}},
        }
    )
    params = mi.traverse(m)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    ref_img = np.array(mi.render(m, spp=1)) * 0.95
    ref = mi.TensorXf(ref_img)

    def forward():
        return np.array(mi.render(m, spp=1))

    def forward_gradient():
        dr.enable_grad(params[key])
        params.update()
        img = mi.render(m, params, spp=1)
        loss = dr.mean(dr.square(img - ref), axis=None)
        dr.backward(loss)
        g = np.array(dr.grad(params[key]))
        dr.disable_grad(params[key])
        params.update()
        return g

    t0 = time.perf_counter()
    forward()
    first_forward = time.perf_counter() - t0
    t0 = time.perf_counter()
    g = forward_gradient()
    first_gradient = time.perf_counter() - t0
    if not np.all(np.isfinite(g)) or not np.any(g != 0):
        raise RuntimeError(f"Mitsuba gradient looks wrong: {g}")
    note = (
        f"Mitsuba {mi.__version__} ({mi.variant()}, drjit {dr.__version__}): direct integrator, 1 spp, "
        f"diffuse BSDF, directional light; gradient of an image loss w.r.t. the diffuse reflectance "
        f"(dr.backward)"
    )
    return {
        "tasks": {
            "Mitsuba direct 1 spp forward": forward,
            "Mitsuba direct 1 spp forward + gradient": forward_gradient,
        },
        "note": note,
        "first_forward": first_forward,
        "first_gradient": first_gradient,
    }


def worker_cli(args) -> dict:
    """`diffwash render` end to end, twice, with a fresh persistent compilation cache."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "DIFFWASH_CACHE_DIR": str(Path(tmp) / "cache"), "PYTHONPATH": str(ROOT)}
        for label in ("cold cache", "warm cache"):
            t0 = time.perf_counter()
            r = subprocess.run(
                [sys.executable, "-m", "diffwash", "render", args.scene, "-o", str(Path(tmp) / "out.png")],
                env=env,
                capture_output=True,
                text=True,
            )
            out[label] = time.perf_counter() - t0
            if r.returncode != 0:
                raise RuntimeError(r.stderr)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import diffwash, trimesh"], env=env, check=True)
        out["python + imports"] = time.perf_counter() - t0
    return out


WORKERS = {
    "jax": worker_jax,
    "grad": worker_grad,
    "raster": worker_raster_table,
    "compare": worker_compare,
    "cli": worker_cli,
}


# ---------------------------------------------------------------------------
# Driver.


def run_worker(name: str, args, env: dict | None = None) -> dict:
    cmd = [sys.executable, __file__, "--worker", name, "--scene", args.scene, "--repeats", str(args.repeats),
           "--rounds", str(args.rounds), "--raster-sizes", *map(str, args.raster_sizes)]  # fmt: skip
    print(f"[bench_render] {name} {env or ''}...", file=sys.stderr, flush=True)
    r = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, **(env or {})})
    if r.returncode != 0:
        raise RuntimeError(f"worker {name} failed:\n{r.stderr}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def ms(t: dict | float) -> str:
    if isinstance(t, dict):
        return f"{t['median'] * 1e3:.1f} ({t['min'] * 1e3:.1f})"
    return f"{t * 1e3:.1f}"


def report(res: dict, args) -> str:
    j, c = res["jax"], res["compare"]
    lines = []
    lines.append(f"### diffwash renderer: {j['size']}, {j['triangles']} triangles, per-pixel, float32, CPU")
    lines.append("")
    lines.append("| measurement | time, ms: median (min) | target |")
    lines.append("| --- | --- | --- |")
    rows = [
        ("forward, visibility cached by `render` (lookup included)", j["forward_cached"], "<= 30"),
        ("forward, visibility passed in", j["forward_visibility_given"], "<= 30"),
        ("forward including rasterization", j["forward_with_raster"], ""),
        ("rasterize alone", j["rasterize"], ""),
        (f"forward + gradient w.r.t. all {j['n_params']} shading parameters (jit)", j["forward_grad"], "<= 100"),
        ("forward, per-vertex shading", j["forward_per_vertex"], ""),
        (f"forward, antialiased ({j['silhouette_items']} silhouette work items)", j["forward_antialias"], ""),
        ("antialiasing preparation (rasterize + silhouette analysis)", j["prepare_antialias"], ""),
    ]
    for name, t, target in rows:
        lines.append(f"| {name} | {ms(t)} | {target} |")
    g = res.get("grad_no_ynn", {})
    if "forward_grad" in g:
        lines.append(f"| forward + gradient, `XLA_FLAGS={NO_YNN}` (another process) | {ms(g['forward_grad'])} | |")
        lines.append(f"| forward, visibility passed in, same flag | {ms(g['forward_visibility_given'])} | |")
    elif g:
        lines.append(f"| forward + gradient with `XLA_FLAGS={NO_YNN}` | not run: {g['error']} | |")
    lines.append("")
    lines.append("| compile (cold process, no persistent cache) | seconds |")
    lines.append("| --- | --- |")
    for name, key in (
        ("rasterize (first call)", "compile_rasterize"),
        ("render, per-pixel (first call)", "compile_render"),
        ("forward + gradient (first call)", "compile_grad"),
        ("render, per-vertex (first call)", "compile_per_vertex"),
        ("antialiasing: analysis + render (first call)", "compile_antialias"),
    ):
        lines.append(f"| {name} | {j[key]:.2f} |")
    if "cli" in res:
        cli = res["cli"]
        lines.append(f"| `diffwash render` end to end: cold cache | {cli['cold cache']:.2f} |")
        lines.append(f"| `diffwash render` end to end: warm persistent cache | {cli['warm cache']:.2f} |")
        lines.append(f"| (of which Python start + `import diffwash, trimesh`) | {cli['python + imports']:.2f} |")
    lines.append("")
    lines.append(
        f"Peak memory (RSS) of the diffwash process: {j['rss_peak']:.0f} MiB in all; "
        f"{j['rss_base']:.0f} MiB after imports and loading the scene; forward passes added "
        f"{j['rss_forward']:.0f} MiB (compiled code, buffers)."
    )
    lines.append("")
    lines.append("### Rasterization cost (warm, median (min), ms)")
    lines.append("")
    sizes = args.raster_sizes
    lines.append("| triangles | " + " | ".join(f"{s}^2" for s in sizes) + " |")
    lines.append("| --- | " + " | ".join("---" for _ in sizes) + " |")
    for label in ("1k", "10k", "100k"):
        cells = [ms(res["raster"][f"{label}/{s}"]) for s in sizes]
        lines.append(f"| {res['raster'][f'{label}/{sizes[0]}']['triangles']} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append(f"### Peers, same scene, alternating in {args.rounds} rounds (median (min) of round medians, ms)")
    lines.append("")
    lines.append("| renderer | time, ms |")
    lines.append("| --- | --- |")
    for k, t in c["times"].items():
        lines.append(f"| {k} | {ms(t)} |")
    for peer in ("opengl", "mitsuba"):
        note = c["notes"].get(peer, "")
        if note.startswith("not run"):
            lines.append(f"| {'OpenGL' if peer == 'opengl' else 'Mitsuba 3'} | {note} |")
    lines.append("")
    lines.append("| ratio (median of per-round ratios) | value |")
    lines.append("| --- | --- |")
    for k, v in c["ratios"].items():
        lines.append(f"| {k} | {v:.2f} |")
    lines.append("")
    for k, v in c["notes"].items():
        lines.append(f"- {k}: {v}")
    if "mitsuba_first_forward" in c:
        lines.append(
            f"- Mitsuba first calls (kernel JIT): forward {c['mitsuba_first_forward']:.2f} s, "
            f"forward + gradient {c['mitsuba_first_gradient']:.2f} s"
        )
    lines.append(f"- machine: {os.cpu_count()} CPU cores, shared with other work; load average at the end "
                 f"{os.getloadavg()[0]:.1f}")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=str(ROOT / "data" / "scenes" / "knot.json"))
    ap.add_argument("--repeats", type=int, default=30, help="warm repeats per timing (default: %(default)s)")
    ap.add_argument("--rounds", type=int, default=6, help="rounds alternating diffwash and peers")
    ap.add_argument("--raster-sizes", type=int, nargs="+", default=[256, 512, 1024])
    ap.add_argument("--quick", action="store_true", help="few repeats (a smoke test of the script)")
    ap.add_argument("--json", metavar="PATH", help="also write the raw results as JSON")
    ap.add_argument("--worker", choices=sorted(WORKERS), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.quick:
        args.repeats, args.rounds = 3, 2
    if args.worker:
        print(json.dumps(WORKERS[args.worker](args)))
        return
    res = {name: run_worker(name, args) for name in ("jax", "raster", "compare", "cli")}
    flags = (os.environ.get("XLA_FLAGS", "") + " " + NO_YNN).strip()
    try:
        res["grad_no_ynn"] = run_worker("grad", args, {"XLA_FLAGS": flags})
    except RuntimeError as e:  # the flag is experimental: a JAX without it refuses it
        res["grad_no_ynn"] = {"error": str(e).splitlines()[-1]}
    text = report(res, args)
    print(text)
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
