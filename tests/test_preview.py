"""The OpenGL preview (exported shaders + LUT, Mesa EGL) against an independent ray-cast evaluation
of diffwash.shading at the pixel centres."""

import numpy as np
import pytest

import diffwash
from diffwash import lut, preview, shading
from diffwash.colorimetry import to_display as srgb_encode

from conftest import DATA

SIZE = (128, 128)


def psnr(a, b):
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1 / mse)


def to_8bit_srgb(linear):
    return np.round(srgb_encode(linear) * 255) / 255


def raycast(scene):
    """Per pixel centre: nearest front-facing triangle hit by the eye ray, its barycentrics and the hit
    point (Moller-Trumbore, each triangle tested against the pixels of its screen bounding box)."""
    cam = scene.camera
    W, H = scene.width, scene.height
    vp = np.asarray(cam.view_projection(W / H), np.float64)
    inv = np.linalg.inv(vp)
    xs, ys = np.meshgrid((np.arange(W) + 0.5) / W * 2 - 1, 1 - (np.arange(H) + 0.5) / H * 2)
    ndc = np.stack([xs.ravel(), ys.ravel()], -1)

    def unproject(z):
        p = np.concatenate([ndc, np.full((len(ndc), 1), z), np.ones((len(ndc), 1))], 1) @ inv.T
        return p[:, :3] / p[:, 3:]

    eye = np.asarray(cam.eye, np.float64)
    d = unproject(1.0) - unproject(-1.0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    v = np.asarray(scene.mesh.vertices, np.float64)
    f = np.asarray(scene.mesh.faces)
    clip = np.concatenate([v, np.ones((len(v), 1))], 1) @ vp.T
    assert np.all(clip[:, 3] > 0), "the reference needs the whole mesh in front of the camera"
    px = (clip[:, 0] / clip[:, 3] + 1) / 2 * W - 0.5  # pixel-centre coordinates
    py = (1 - clip[:, 1] / clip[:, 3]) / 2 * H - 0.5
    tri = np.full(W * H, -1)
    bary = np.zeros((W * H, 2))
    best = np.full(W * H, np.inf)
    for k, (a, b, c) in enumerate(f):
        x0, x1 = int(np.floor(min(px[a], px[b], px[c]))), int(np.ceil(max(px[a], px[b], px[c])))
        y0, y1 = int(np.floor(min(py[a], py[b], py[c]))), int(np.ceil(max(py[a], py[b], py[c])))
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, W - 1), min(y1, H - 1)
        if x0 > x1 or y0 > y1:
            continue
        e1, e2 = v[b] - v[a], v[c] - v[a]
        ids = (np.arange(y0, y1 + 1)[:, None] * W + np.arange(x0, x1 + 1)[None]).ravel()
        D = d[ids]
        pvec = np.cross(D, e2)
        det = pvec @ e1
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_det = 1 / det
            tvec = eye - v[a]
            u = (pvec @ tvec) * inv_det
            qvec = np.cross(tvec, e1)
            w = (D @ qvec) * inv_det
            t = (e2 @ qvec) * inv_det
        eps = 1e-9  # shared edges belong to both triangles: no cracks between them
        hit = (u >= -eps) & (w >= -eps) & (u + w <= 1 + eps) & (t > 0) & (t < best[ids])
        hit &= det > 0  # front-facing (counter-clockwise seen from the eye): back faces are culled
        sel = ids[hit]
        tri[sel], best[sel] = k, t[hit]
        bary[sel] = np.stack([u[hit], w[hit]], -1)
    points = eye + d * np.where(np.isfinite(best), best, 0)[:, None]
    return tri.reshape(H, W), bary.reshape(H, W, 2), points.reshape(H, W, 3)


def reference(scene, mode, hits=None):
    """Linear RGB at the pixel centres, evaluated with diffwash.shading from the ray hits."""
    tri, bary, points = raycast(scene) if hits is None else hits
    p = scene.params
    f = np.asarray(scene.mesh.faces)
    hit = tri >= 0
    t = f[tri[hit]]
    b = np.concatenate([1 - bary[hit].sum(-1, keepdims=True), bary[hit]], -1)
    eye = np.asarray(scene.camera.eye, np.float64)
    L = np.asarray(p.light, np.float64) / np.linalg.norm(np.asarray(p.light))
    normals = np.asarray(scene.mesh.normals, np.float64)
    if mode == "per-pixel":
        N = np.einsum("pk,pkc->pc", b, normals[t])
        N /= np.linalg.norm(N, axis=-1, keepdims=True)
        V = eye - points[hit]
        V /= np.linalg.norm(V, axis=-1, keepdims=True)
        wash, unlit = (np.asarray(a) for a in shading.thicknesses(N, L, V, p))
    else:
        verts = np.asarray(scene.mesh.vertices, np.float64)
        Vv = eye - verts
        Vv /= np.linalg.norm(Vv, axis=-1, keepdims=True)
        wv, uv = (np.asarray(a) for a in shading.thicknesses(normals, L, Vv, p))
        # 3D barycentrics of the hit point are the perspective-correct interpolation weights.
        wash = np.einsum("pk,pk->p", b, wv[t])
        unlit = np.einsum("pk,pk->p", b, uv[t])
    img = np.broadcast_to(np.asarray(p.paper, np.float64), hit.shape + (3,)).copy()
    img[hit] = np.asarray(shading.glaze(p, wash, unlit))
    return img, hit


@pytest.fixture(scope="module")
def ctx():
    c = preview.create_context()
    yield c
    c.release()


@pytest.fixture(scope="module")
def sphere():
    return diffwash.load_scene(DATA / "scenes" / "sphere.json", size=SIZE)


@pytest.fixture(scope="module")
def references(sphere):
    hits = raycast(sphere)
    return {m: reference(sphere, m, hits) for m in ("per-pixel", "per-vertex")}


@pytest.mark.parametrize("mode", ["per-pixel", "per-vertex"])
def test_preview_matches_raycast_reference(ctx, sphere, references, mode):
    ref, hit = references[mode]
    frame = preview.render(sphere, shading=mode, ctx=ctx)
    assert frame.shape == (*SIZE[::-1], 3)
    ref8 = to_8bit_srgb(ref)
    assert psnr(frame, ref8) >= 40
    # Away from the silhouette (where a pixel centre may fall either way) they agree to a level.
    interior = hit & np.roll(hit, 1, 0) & np.roll(hit, -1, 0) & np.roll(hit, 1, 1) & np.roll(hit, -1, 1)
    assert np.abs(frame - ref8)[interior].max() <= 1.5 / 255
    # Uncovered pixels are bare paper.
    outside = ~hit & ~np.roll(hit, 1, 0) & ~np.roll(hit, -1, 0) & ~np.roll(hit, 1, 1) & ~np.roll(hit, -1, 1)
    assert np.abs(frame[outside] - to_8bit_srgb(np.asarray(sphere.params.paper))).max() < 1e-6


def test_preview_linear_and_km_paths(ctx, sphere, references):
    ref, hit = references["per-pixel"]
    linear = preview.render(sphere, linear=True, ctx=ctx)
    interior = hit & np.roll(hit, 1, 0) & np.roll(hit, -1, 0) & np.roll(hit, 1, 1) & np.roll(hit, -1, 1)
    assert np.abs(linear - ref)[interior].max() < 2e-3
    km = preview.render(sphere, colour="km", linear=True, ctx=ctx)
    assert np.abs(km - ref)[interior].max() < 2e-3
    # The R/T LUT composited over the paper in the shader gives the same picture.
    rt = preview.render(sphere, lut=lut.bake(sphere, 256, kind="rt"), ctx=ctx)
    assert psnr(rt, to_8bit_srgb(ref)) >= 40


def test_preview_with_loaded_png8_lut(ctx, sphere, references, tmp_path):
    lut.save(tmp_path / "lut.png", lut.bake(sphere, 256), "png8")
    frame = preview.render(sphere, lut=lut.load(tmp_path / "lut.json"), ctx=ctx)
    assert psnr(frame, to_8bit_srgb(references["per-pixel"][0])) >= 40


def test_preview_follows_params(ctx, sphere):
    """Changing a constant changes the picture (the uniforms reach the shader)."""
    a = preview.render(sphere, ctx=ctx)
    p = sphere.params
    b = preview.render(sphere, type(p)(**{**{k: getattr(p, k) for k in p.__dataclass_fields__}, "gain": 0.9}), ctx=ctx)
    assert np.abs(a - b).max() > 0.05


# --- against the renderer -------------------------------------------------------------------------


def small_scene_file(folder, name, mesh=None, **overrides):
    import json

    data = json.loads((DATA / "scenes" / f"{name}.json").read_text())
    data["mesh"] = str((DATA / "scenes" / data["mesh"]).resolve()) if mesh is None else str(mesh)
    data["image"] = {"width": SIZE[0], "height": SIZE[1]}
    data.update(overrides)
    path = folder / f"{name}-small.json"
    path.write_text(json.dumps(data))
    return path


@pytest.mark.parametrize("mode", ["per-pixel", "per-vertex"])
@pytest.mark.parametrize("mesh", ["sphere", "knot-1k"])
def test_preview_matches_render(ctx, tmp_path, mode, mesh):
    """The real-time path (GLSL + 256^2 LUT in OpenGL) and `diffwash.render` are the same image."""
    name = "sphere" if mesh == "sphere" else "knot"
    path = small_scene_file(tmp_path, name, DATA / "meshes" / f"{mesh}.ply", shading=mode)
    scene = diffwash.load_scene(path)
    rendered = to_8bit_srgb(np.asarray(diffwash.render(scene)))
    frame = preview.render(scene, lut=lut.bake(scene, 256), ctx=ctx)
    assert psnr(frame, rendered) >= 40


def test_open_mesh_two_sided_matches_render(ctx, tmp_path):
    """An open mesh seen from inside: back faces drawn with the normal turned towards the eye."""
    import trimesh

    sphere = trimesh.load(DATA / "meshes" / "sphere.ply", process=False)
    keep = sphere.vertices[sphere.faces].mean(axis=1)[:, 2] < 0.3  # cut the cap facing the camera
    bowl = trimesh.Trimesh(sphere.vertices, sphere.faces[keep], vertex_normals=sphere.vertex_normals, process=False)
    bowl.export(tmp_path / "bowl.ply")
    for mode in ("per-pixel", "per-vertex"):
        path = small_scene_file(tmp_path, "sphere", tmp_path / "bowl.ply", shading=mode, camera={"eye": [0.6, 0.8, 3.0], "target": [0, 0, 0]})
        scene = diffwash.load_scene(path)
        assert not scene.cull_backfaces
        rendered = to_8bit_srgb(np.asarray(diffwash.render(scene)))
        frame = preview.render(scene, ctx=ctx)
        assert psnr(frame, rendered) >= 40
