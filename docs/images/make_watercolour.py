"""The figures of docs/watercolour.md: the knot scene with the watercolour look's effects, one by one and together.

    python docs/images/make_watercolour.py [--out docs/images] [--only NAME ...]

Stage 1 of issue 13: the look's operators (diffwash.look) applied to what the renderer computes today
(per-pixel thicknesses, positions and normals of data/scenes/knot.json), outside `diffwash.render`, which
stage 2 wires them into. The per-pixel geometry comes from the renderer's own stages (private helpers of
diffwash._render), the light's depth pass from its rasterizer, fed `look.light_clip`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import diffwash  # noqa: E402
from diffwash import look as wl  # noqa: E402
from diffwash import pigments, shading  # noqa: E402
from diffwash._io import write_png  # noqa: E402
from diffwash.colorimetry import to_display as srgb_encode  # noqa: E402

SCENE = ROOT / "data" / "scenes" / "knot.json"
SHADOW_SIZE = wl.SHADOW_MAP_SIZE
HATCH_SCALE = 190.0  # TAM level-0 texels per object unit: about one texel per pixel on the knot at 512^2


def pixel_geometry(scene) -> dict:
    """Per covered pixel: index, triangle, barycentrics, world position and normal, eye depth, the model's thicknesses."""
    from diffwash._render import surface, surface_thicknesses
    from diffwash.ops import barycentrics, interpolate

    vis = diffwash.rasterize(scene)
    mesh, W, H = scene.mesh, scene.width, scene.height
    faces = jnp.asarray(mesh.faces, jnp.int32)
    vertices = jnp.asarray(mesh.vertices)
    surf, clip = surface(vertices, faces, jnp.asarray(mesh.normals), scene.camera, vis, np.bool_(not scene.cull_backfaces),
                         width=W, height=H, mode="per-pixel")  # fmt: skip
    wash, unlit = surface_thicknesses(surf, scene.params)
    bary, _ = barycentrics(clip, faces, vis.pixel_tri, vis.pixels, W, H)
    P = interpolate(vertices, faces, vis.pixel_tri, bary)
    keep = np.asarray(vis.pixels) < W * H
    eye = np.asarray(scene.camera.eye, np.float64)
    forward = np.asarray(scene.camera.target, np.float64) - eye
    forward /= np.linalg.norm(forward)
    P = np.asarray(P)[keep]
    return {
        "pixels": np.asarray(vis.pixels)[keep],
        "tri": np.asarray(vis.pixel_tri)[keep],
        "bary": np.asarray(bary)[keep],
        "P": P,
        "N": np.asarray(surf.N)[keep],
        "depth": (P - eye) @ forward,
        "wash": np.asarray(wash)[keep],
        "unlit": np.asarray(unlit)[keep],
    }


def shadow_map(scene, size: int = SHADOW_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """The light's depth map and matrix: the renderer's rasterizer on `look.light_clip`, then `look.light_depth`."""
    from diffwash.ops import rasterize

    vertices, faces = np.asarray(scene.mesh.vertices), np.asarray(scene.mesh.faces)
    vp = np.asarray(wl.light_view_projection(vertices, scene.params.light))
    # light_clip's w grows with the distance from the light: the rasterizer's depth order is the light's.
    tri = rasterize(wl.light_clip(vertices, vp), faces, (size, size)).tri_id
    return np.asarray(wl.light_depth(vertices, faces, vp, tri)), vp


class Extras(eqx.Module):
    """What the look needs beyond the plain scene: a mix map and second pigments, the stroke layer, the TAM."""

    mix: np.ndarray | None = None
    wash_b: object = None
    unlit_b: object = None
    strokes: np.ndarray | None = None
    tam: list | None = None


def render_look(scene, look: wl.Look, geo: dict, screen, extras: Extras, shadow: tuple | None) -> np.ndarray:
    """The knot through the look's pipeline: surface terms -> G-buffer -> image terms -> glaze -> paper shading."""
    p = scene.params
    H, W = scene.height, scene.width
    faces = np.asarray(scene.mesh.faces)

    def interp(per_vertex):
        return (np.asarray(per_vertex)[faces[geo["tri"]]] * geo["bary"]).sum(-1)

    sh = None
    if shadow is not None:
        depth, vp = shadow
        offset = wl.normal_offset(vp, depth.shape[0])
        sh = wl.shadow(depth, vp, geo["P"], look.shadow_bias, normals=geo["N"], normal_offset=offset)
    hatch = None
    if extras.tam is not None:
        fov = np.radians(float(scene.camera.fov_y))
        pixel = geo["depth"] * 2 * np.tan(fov / 2) / H
        hatch = wl.hatch_samples(extras.tam, geo["P"], geo["N"], pixel, HATCH_SCALE)
    w, u = wl.surface_terms(geo["wash"], geo["unlit"], look, unlit_max=float(p.k_unlit), shadow=sh, hatch=hatch)
    mix = interp(extras.mix) if extras.mix is not None else np.zeros(len(w))
    stroke = interp(extras.strokes) if extras.strokes is not None else np.zeros(len(w))
    g = np.zeros((H * W, 4))
    g[geo["pixels"]] = np.stack([np.asarray(w), np.asarray(u), mix, stroke], -1)
    g = jnp.asarray(g.reshape(H, W, 4))
    wash_b = extras.wash_b if extras.wash_b is not None else p.wash
    unlit_b = extras.unlit_b if extras.unlit_b is not None else p.unlit
    pigs = wl.Pigments(*(wl.pigment_look(q, screen.paper) for q in (p.wash, wash_b, p.unlit, unlit_b)))
    rgb = wl.compose(g, wl.tile(screen, H, W), look, pigs, lambda a, b, m: wl.glaze_mix(p, wash_b, unlit_b, a, b, m))
    return np.asarray(rgb)


def plain(scene) -> np.ndarray:
    return np.asarray(diffwash.render(scene))


def save(path: Path, linear: np.ndarray) -> None:
    """A PNG, or a JPEG (quality 92) for a `.jpg` path: the full-size noisy pictures stay under 300 KB."""
    if path.suffix == ".jpg":
        from PIL import Image

        Image.fromarray(np.round(srgb_encode(linear) * 255).astype(np.uint8)).save(path, quality=92)
    else:
        write_png(path, srgb_encode(linear))
    print(f"{path}: {path.stat().st_size // 1024} KB")


def crop(img: np.ndarray, box) -> np.ndarray:
    r0, c0 = box
    return img[r0 : r0 + 256, c0 : c0 + 256]


def side_by_side(*images: np.ndarray) -> np.ndarray:
    """Images side by side with 4-pixel white gaps."""
    gap = np.ones((images[0].shape[0], 4, 3))
    out = [images[0]]
    for im in images[1:]:
        out += [gap, im]
    return np.concatenate(out, axis=1)


def only(**values) -> wl.Look:
    """Every effect off but the named ones, at their defaults unless given."""
    return wl.Look(**{**dict.fromkeys(wl.DEFAULT_LOOK, 0.0), **{k: wl.DEFAULT_LOOK[k] if v is None else v for k, v in values.items()}})


def strokes_of(mesh, **kw) -> np.ndarray:
    return wl.stroke_field(np.asarray(mesh.vertices), np.asarray(mesh.faces), np.asarray(mesh.normals), direction="max", **kw)


def with_mesh(scene, vertices, faces, normals):
    from diffwash._scene import Mesh

    mesh = Mesh(vertices=np.asarray(vertices, np.float64), faces=np.asarray(faces, np.int32), normals=np.asarray(normals, np.float64),
                closed=scene.mesh.closed)  # fmt: skip
    return eqx.tree_at(lambda s: s.mesh, scene, mesh)


def lighter(scene):
    """The same scene painted with a lighter hand (thinner glazes), where the look's effects show most."""
    return eqx.tree_at(lambda s: (s.params.k_wash, s.params.k_unlit), scene, (np.float64(0.45), np.float64(0.55)))


def strokes_figure(scene, screen, out: Path) -> None:
    """The stroke layer as a vertex attribute on the 1k, 10k and 100k knots, and on the 1k knot subdivided."""
    panels = []
    lk = only(strokes=0.35)
    for name in ("1k", "10k", "100k", "1k-subdivided"):
        mesh = diffwash.load_mesh(ROOT / "data" / "meshes" / f"knot-{name.split('-')[0]}.ply")
        v, f, n = np.asarray(mesh.vertices), np.asarray(mesh.faces), np.asarray(mesh.normals)
        if name.endswith("subdivided"):
            v, f, n = wl._strokes.subdivide(v, f, n, max_edge=0.035)
        sc = lighter(with_mesh(scene, v, f, n))
        img = render_look(sc, lk, pixel_geometry(sc), screen, Extras(strokes=wl.stroke_field(v, f, n, direction="max")), None)
        panels.append(crop(img, (40, 40)))
    save(out / "watercolour-strokes-meshes.jpg", side_by_side(*panels))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "images")
    ap.add_argument("--only", nargs="*", default=None)
    args = ap.parse_args(argv)
    want = lambda name: args.only is None or name in args.only  # noqa: E731
    t0 = time.perf_counter()
    scene = diffwash.load_scene(SCENE)
    light = lighter(scene)
    geo, geo_light = pixel_geometry(scene), pixel_geometry(light)
    screen = wl.screen_textures(shape=(512, 512), seed=0)
    strokes = strokes_of(scene.mesh)
    shadow = shadow_map(scene)
    full = render_look(scene, wl.Look(), geo, screen, Extras(strokes=strokes), shadow)
    if want("knot"):
        save(args.out / "watercolour-knot.jpg", side_by_side(plain(scene), full))
    if want("lighter"):
        save(args.out / "watercolour-lighter.jpg", side_by_side(plain(light), render_look(light, wl.Look(), geo_light, screen, Extras(strokes=strokes), shadow)))
    base = render_look(light, wl.OFF, geo_light, screen, Extras(), None)
    effects = {
        "paper": (only(granulation=None, density=None, paper_shading=None), Extras(), None, (60, 60)),
        "edges": (only(edge_darkening=None, edge_width=None), Extras(), None, (60, 60)),
        "unevenness": (only(turbulence=None, dispersion=None), Extras(), None, (60, 60)),
        "strokes": (only(strokes=None), Extras(strokes=strokes), None, (60, 60)),
        "shadow": (only(shadow=None, shadow_bias=None), Extras(), shadow, (230, 180)),
    }
    for name, (lk, ex, sh, box) in effects.items():
        if want(name):
            save(args.out / f"watercolour-{name}.png", side_by_side(crop(base, box), crop(render_look(light, lk, geo_light, screen, ex, sh), box)))
    if want("hatching"):
        tam = wl.tonal_art_map()
        pen = eqx.tree_at(lambda q: (q.hatching, q.strokes), wl.Look(), (1.0, 0.0))
        img = render_look(light, pen, geo_light, screen, Extras(tam=tam), shadow)
        save(args.out / "watercolour-hatching.png", side_by_side(crop(base, (60, 60)), crop(img, (60, 60))))
    if want("mix"):
        lib = pigments.library()
        ex = Extras(mix=wl.mix_along_axis(np.asarray(scene.mesh.vertices), [1.0, -0.6, 0.0], softness=0.6), wash_b=lib["Cadmium Yellow"],
                    unlit_b=lib["Hookers Green"], strokes=strokes)  # fmt: skip
        save(args.out / "watercolour-mix.jpg", side_by_side(full, render_look(scene, wl.Look(), geo, screen, ex, shadow)))
    if want("strokes-meshes"):
        strokes_figure(scene, screen, args.out)
    print(f"done in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
