"""The render core on an accelerator: rasterize, forward, forward + gradient and batched forward,
against nvdiffrast in the same run when it is importable.

    python benchmarks/bench_gpu.py [--sizes 512 1024 2048] [--repeats 20] [--views 4] [--json OUT.json]

Runs on whatever device JAX has (a GPU with JAX's CUDA build; the CPU otherwise, where nvdiffrast
is skipped) and prints a Markdown table per size for the 100k-triangle knot (`data/meshes/knot-100k.ply`,
the camera and model of `data/scenes/knot.json`), naming the device:

- *rasterize*: `diffwash.ops.rasterize` jitted (clip-space positions -> triangle ids and depths), with a
  fixed fragment budget, so there is no host round trip;
- *forward, visibility reused*: `diffwash.render(scene)` with the visibility reused (what a material
  fit runs each step);
- *forward incl. rasterization*: one jitted program from vertex positions to the image;
- *forward + gradient incl. rasterization*: one jitted program from vertex positions and shading
  parameters to an image loss and its gradient with respect to both, rasterizing inside;
- *batched forward*: `--views` views (cameras orbiting the knot) rendered by one `jax.vmap`ped,
  jitted program, rasterization included; the time per batch.

nvdiffrast (PyTorch) runs the same pipeline: `rasterize`, `interpolate` of normals and positions, the
watercolour thickness model and Kubelka-Munk glazes written in torch (the formulas of
`diffwash.shading` and `diffwash.km`), the same loss and `backward()` with respect to positions and the
same parameters; on the GPU, times are taken after `torch.cuda.synchronize()`. Ratios are diffwash's
median over nvdiffrast's, measured alternately in one process.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_render import rss_mb, timed  # noqa: E402


def _scene(size: int):
    import jax.numpy as jnp

    import diffwash

    scene = diffwash.load_scene(ROOT / "data" / "scenes" / "knot.json", size=(size, size))
    mesh = dataclasses.replace(
        scene.mesh,
        vertices=jnp.asarray(scene.mesh.vertices, jnp.float32),
        faces=jnp.asarray(scene.mesh.faces, jnp.int32),
        normals=jnp.asarray(scene.mesh.normals, jnp.float32),
    )
    return dataclasses.replace(scene, mesh=mesh)


def _orbit(camera, n: int):
    """`n` cameras orbiting the scene camera's target at its distance, stacked on a leading axis."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    eye, target = np.asarray(camera.eye), np.asarray(camera.target)
    d = eye - target
    cams = []
    for k in range(n):
        a = 2 * np.pi * k / n
        rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        cams.append(dataclasses.replace(camera, eye=jnp.asarray(target + rot @ d, jnp.float32)))
    return jax.tree.map(lambda *x: jnp.stack([jnp.asarray(v, jnp.float32) for v in x]), *cams)


def diffwash_tasks(size: int, views: int) -> tuple[dict, dict]:
    import jax
    import jax.numpy as jnp

    import diffwash
    from diffwash import ops

    scene = _scene(size)
    aspect = scene.width / scene.height
    faces = scene.mesh.faces
    info = {"triangles": int(faces.shape[0])}

    clip0 = ops.clip_positions(scene.mesh.vertices, scene.camera.view_projection(aspect))
    capacity = ops.required_capacity(clip0, faces, (size, size), cull_backfaces=True)
    exact = ops.rasterize(clip0, faces, (size, size), cull_backfaces=True, capacity=capacity)
    info["fragment_jobs"] = capacity
    info["covered"] = int(jnp.sum(exact.tri_id >= 0))

    @jax.jit
    def rasterize(vertices, camera):
        clip = ops.clip_positions(vertices, camera.view_projection(aspect))
        return ops.rasterize(clip, faces, (size, size), cull_backfaces=True, capacity=capacity).tri_id

    vis = diffwash.rasterize(scene)
    target = diffwash.render(scene, visibility=vis) * 0.95

    def moved(vertices):
        return dataclasses.replace(scene, mesh=dataclasses.replace(scene.mesh, vertices=vertices))

    forward = jax.jit(lambda vertices, params: diffwash.render(moved(vertices), params))

    @jax.jit
    @functools.partial(jax.value_and_grad, argnums=(0, 1))
    def forward_grad(vertices, params):
        return jnp.mean((diffwash.render(moved(vertices), params) - target) ** 2)

    cams = _orbit(scene.camera, views)

    @jax.jit
    def batched(cameras, params):
        return jax.vmap(lambda c: diffwash.render(dataclasses.replace(scene, camera=c), params))(cameras)

    params = scene.params
    v = scene.mesh.vertices
    tasks = {
        "rasterize": lambda: jax.block_until_ready(rasterize(v, scene.camera)),
        "forward, visibility reused": lambda: jax.block_until_ready(diffwash.render(scene, visibility=vis)),
        "forward incl. rasterization": lambda: jax.block_until_ready(forward(v, params)),
        "forward + gradient incl. rasterization": lambda: jax.block_until_ready(forward_grad(v, params)),
        f"batched forward ({views} views) incl. rasterization": lambda: jax.block_until_ready(batched(cams, params)),
    }
    compile_times = {}
    for name, fn in tasks.items():
        t0 = time.perf_counter()
        fn()
        compile_times[name] = time.perf_counter() - t0
    info["first_call_s"] = compile_times
    return tasks, info


def nvdiffrast_tasks(size: int, views: int) -> tuple[dict, str]:
    """The same four measurements with nvdiffrast (CUDA) and torch, or a reason why not."""
    try:
        import nvdiffrast.torch as dr
        import torch
    except ImportError as e:
        return {}, f"nvdiffrast not importable ({e})"
    if not torch.cuda.is_available():
        return {}, "nvdiffrast needs CUDA (torch.cuda.is_available() is False)"
    import numpy as np

    from diffwash import km

    scene = _scene(size)
    dev = "cuda"
    glctx = dr.RasterizeCudaContext()
    vp = torch.tensor(np.asarray(scene.camera.view_projection(1.0)), dtype=torch.float32, device=dev)
    v = torch.tensor(np.asarray(scene.mesh.vertices), dtype=torch.float32, device=dev)
    n = torch.tensor(np.asarray(scene.mesh.normals), dtype=torch.float32, device=dev)
    f = torch.tensor(np.asarray(scene.mesh.faces), dtype=torch.int32, device=dev)
    p = scene.params
    eye = torch.tensor(np.asarray(scene.camera.eye), dtype=torch.float32, device=dev)
    light = torch.tensor(np.asarray(p.light), dtype=torch.float32, device=dev)
    light = light / light.norm()
    consts = {k: torch.tensor(float(getattr(p, k)), device=dev) for k in
              ("k_wash", "k_specular", "shininess", "k_unlit", "gain", "bias", "wash_reduction")}  # fmt: skip
    pig = {k: torch.tensor(np.asarray(x), dtype=torch.float32, device=dev) for k, x in
           (("wK", p.wash.K), ("wS", p.wash.S), ("uK", p.unlit.K), ("uS", p.unlit.S), ("paper", p.paper))}  # fmt: skip

    def bias(t, b):
        b = b.clamp(1e-6, 1 - 1e-6)
        return t / ((1 / b - 2) * (1 - t) + 1)

    def gain(t, g):
        return torch.where(t < 0.5, bias(2 * t.clamp(max=0.5), 1 - g) / 2, 1 - bias(2 - 2 * t.clamp(min=0.5), 1 - g) / 2)

    def layer(K, S, x):  # diffwash.km.layer's exponential branch with its series where beta x < 1
        q = K * (K + 2 * S)
        z = q * x * x
        small = z < 1
        zs = torch.where(small, z, torch.zeros_like(z))
        ch_s = sum(c * zs**i for i, c in enumerate(km._CH_COEFFS))
        sh_s = x * sum(c * zs**i for i, c in enumerate(km._SH_COEFFS))
        beta = torch.sqrt(torch.where(small, torch.ones_like(q), q))
        bx = torch.where(small, torch.ones_like(z), beta * x)
        e1 = torch.exp(-bx)
        ch = torch.where(small, ch_s, (1 + e1 * e1) / 2)
        sh = torch.where(small, sh_s, -torch.expm1(-2 * bx) / (2 * beta))
        d = (S + K) * sh + ch
        return S * sh / d, torch.where(small, torch.ones_like(e1), e1) / d

    def shade(verts, cam_vp):
        clip = torch.cat([verts, torch.ones_like(verts[:, :1])], 1) @ cam_vp.T
        rast, _ = dr.rasterize(glctx, clip[None], f, resolution=[size, size])
        attr = torch.cat([n, verts], 1)[None]
        out, _ = dr.interpolate(attr, rast, f)
        N = torch.nn.functional.normalize(out[..., :3], dim=-1)
        V = torch.nn.functional.normalize(eye - out[..., 3:], dim=-1)
        H = torch.nn.functional.normalize(light + V, dim=-1)
        ndh = (H * N).sum(-1).clamp(0, 1)
        ndl = (light * N).sum(-1)
        u = gain(bias((1 - ndl).clamp(0, 1), consts["bias"]), consts["gain"])
        wash = (1 - ndh ** consts["shininess"]) * consts["k_specular"] * consts["k_wash"] * (1 - consts["wash_reduction"] * u)
        Rw, Tw = layer(pig["wK"], pig["wS"], wash[..., None])
        Ru, Tu = layer(pig["uK"], pig["uS"], (consts["k_unlit"] * u)[..., None])
        d = 1 - Ru * Rw
        R, T = Ru + Tu * Tu * Rw / d, Tu * Tw / d
        c = R + T * T * pig["paper"] / (1 - R * pig["paper"])
        covered = (rast[..., 3:] > 0).float()
        return c * covered + pig["paper"] * (1 - covered), rast

    with torch.no_grad():
        target, rast0 = shade(v, vp)
        target = target * 0.95
    vg = v.clone().requires_grad_(True)
    for t in consts.values():
        t.requires_grad_(True)

    def sync(x=None):
        torch.cuda.synchronize()
        return x

    def forward_grad():
        vg.grad = None
        img, _ = shade(vg, vp)
        loss = ((img - target) ** 2).mean()
        loss.backward()
        return sync()

    vps = [vp] * views
    tasks = {
        "rasterize": lambda: sync(dr.rasterize(glctx, (torch.cat([v, torch.ones_like(v[:, :1])], 1) @ vp.T)[None], f,
                                               resolution=[size, size])),  # fmt: skip
        "forward incl. rasterization": lambda: sync(shade(v, vp)),
        "forward + gradient incl. rasterization": forward_grad,
        f"batched forward ({views} views) incl. rasterization": lambda: sync([shade(v, m) for m in vps]),
    }
    for fn in tasks.values():
        fn()
    return tasks, f"nvdiffrast {getattr(dr, '__version__', '?')}, torch {torch.__version__}, {torch.cuda.get_device_name()}"


def measure(size: int, args) -> dict:
    ours, info = diffwash_tasks(size, args.views)
    peers, note = nvdiffrast_tasks(size, args.views)
    times = {("diffwash", k): [] for k in ours} | {("nvdiffrast", k): [] for k in peers}
    per_round = max(1, args.repeats // args.rounds)
    for _ in range(args.rounds):
        for k, fn in ours.items():
            times[("diffwash", k)].append(timed(fn, per_round)["median"])
            if k in peers:
                times[("nvdiffrast", k)].append(timed(peers[k], per_round)["median"])
    rows = []
    for k in ours:
        a = times[("diffwash", k)]
        row = {"measure": k, "diffwash_ms": 1e3 * statistics.median(a)}
        if k in peers:
            b = times[("nvdiffrast", k)]
            row["nvdiffrast_ms"] = 1e3 * statistics.median(b)
            row["ratio"] = statistics.median(x / y for x, y in zip(a, b))
        rows.append(row)
    return {"size": size, "rows": rows, "info": info, "nvdiffrast": note, "rss_peak_mb": rss_mb()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--views", type=int, default=4)
    parser.add_argument("--json", type=Path, help="also write the results as JSON")
    args = parser.parse_args()
    import jax

    dev = jax.devices()[0]
    device = f"{dev.platform}: {getattr(dev, 'device_kind', dev)} (jax {jax.__version__}, {jax.device_count()} device(s))"
    results = {"device": device, "sizes": [measure(s, args) for s in args.sizes]}
    print(f"# diffwash render core on {device}\n")
    for r in results["sizes"]:
        info = r["info"]
        print(f"## {r['size']}x{r['size']}, {info['triangles']} triangles ({info['covered']} pixels covered)\n")
        print(f"nvdiffrast: {r['nvdiffrast']}. Peak RSS so far {r['rss_peak_mb']:.0f} MiB.\n")
        print("| measure | diffwash (ms) | nvdiffrast (ms) | ratio | diffwash first call (s) |")
        print("| --- | ---: | ---: | ---: | ---: |")
        for row in r["rows"]:
            nv = f"{row['nvdiffrast_ms']:.2f}" if "nvdiffrast_ms" in row else "-"
            ratio = f"{row['ratio']:.2f}" if "ratio" in row else "-"
            first = info["first_call_s"][row["measure"]]
            print(f"| {row['measure']} | {row['diffwash_ms']:.2f} | {nv} | {ratio} | {first:.2f} |")
        print()
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
