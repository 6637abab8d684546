"""The render core's contracts: batches of views, strips of big images, caching without host copies,
and compiled kernels that do not depend on pigment labels."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import knot_scene

import diffwash
from diffwash import _render
from diffwash._cache import leaf_key

W, H = 48, 40


def small_scene(shading="per-pixel", **extra):
    return knot_scene("knot-1k.ply", W, H, shading, **extra)


def _cameras(scene, n=3):
    eyes = [[0.4, 0.6, 3.0], [1.5, 0.2, 2.6], [-1.0, 1.4, 2.5]][:n]
    return [dataclasses.replace(scene.camera, eye=np.asarray(e, np.float64)) for e in eyes]


@pytest.mark.parametrize("antialias", [False, True])
def test_render_views_matches_one_render_per_view(antialias):
    scene = small_scene()
    cams = _cameras(scene)
    batch = np.asarray(diffwash.render_views(scene, cams, antialias=antialias))
    assert batch.shape == (3, H, W, 3)
    for i, cam in enumerate(cams):
        one = np.asarray(diffwash.render(dataclasses.replace(scene, camera=cam), antialias=antialias))
        np.testing.assert_allclose(batch[i], one, atol=1e-12)
    assert np.abs(batch[0] - batch[1]).max() > 0.1  # really different views


def test_render_views_under_jit_with_traced_cameras_and_gradients():
    scene = small_scene()
    cams = jax.tree.map(lambda *x: jnp.stack([jnp.asarray(a) for a in x]), *_cameras(scene))
    f = jax.jit(lambda c, p: diffwash.render_views(scene, c, p))
    np.testing.assert_allclose(np.asarray(f(cams, scene.params)), np.asarray(diffwash.render_views(scene, cams)), atol=1e-10)
    g = jax.grad(lambda p: jnp.sum(diffwash.render_views(scene, cams, p) ** 2))(scene.params)
    assert np.isfinite(float(g.gain)) and float(g.gain) != 0


@pytest.mark.parametrize("antialias", [False, True])
def test_strips_make_the_same_image(monkeypatch, antialias):
    """Big images render in strips (bounded memory); the strips, joined, are the image."""
    scene = small_scene()
    whole = np.asarray(diffwash.render_rgba(scene, antialias=antialias))
    strips = list(_render.render_strips(scene, antialias=antialias, alpha=True, rows=16))  # the last one shorter
    assert [r for r, _ in strips] == [0, 16, 32]
    joined = np.concatenate([np.asarray(s) for _, s in strips])
    np.testing.assert_allclose(joined, whole, atol=1e-9)
    # render() itself switches to strips (of the rows above, so it reuses their compiled kernels)
    monkeypatch.setattr(_render, "TILE_PIXELS", W * 16)
    _render.clear_visibility_cache()
    np.testing.assert_allclose(np.asarray(diffwash.render_rgba(scene, antialias=antialias)), whole, atol=1e-9)


def test_relabelling_a_pigment_compiles_nothing():
    scene = small_scene()
    diffwash.render(scene)
    diffwash.lut.bake(scene, 16)
    before = (_render._render_kernel._cache_size(), diffwash.lut._bake_colour._cache_size())
    renamed = dataclasses.replace(scene.params, wash=dataclasses.replace(scene.params.wash, name="Another Rose"))
    diffwash.render(scene, renamed)
    diffwash.lut.bake(renamed, 16)
    assert (_render._render_kernel._cache_size(), diffwash.lut._bake_colour._cache_size()) == before


def test_visibility_of_device_arrays_is_keyed_by_identity_without_reading_them():
    x = jnp.arange(6.0)
    key = leaf_key(x)
    x.delete()  # reading its values now raises: the key did not need them
    assert key[0] == "jax"
    with pytest.raises(RuntimeError):
        np.asarray(x)
    scene = small_scene()
    mesh = dataclasses.replace(scene.mesh, vertices=jnp.asarray(scene.mesh.vertices), faces=jnp.asarray(scene.mesh.faces))
    device_scene = dataclasses.replace(scene, mesh=mesh)
    _render.clear_visibility_cache()
    diffwash.render(device_scene)
    first = _render._cache.values()[0]
    diffwash.render(device_scene, dataclasses.replace(device_scene.params, gain=0.3))
    assert len(_render._cache) == 1 and _render._cache.values()[0] is first


def test_a_render_hashes_each_host_array_once(monkeypatch, tmp_path):
    """A look render keys three caches with the mesh's NumPy arrays (its visibility, the light's depth pass, the
    shadow at the vertices): within one render each array's bytes are hashed once (`_cache.same_arrays`); a change
    between renders still gives a new key."""
    import zlib

    from diffwash import _cache

    hashed = []
    crc = zlib.crc32
    monkeypatch.setattr(_cache.zlib, "crc32", lambda b: hashed.append(len(b)) or crc(b))
    x = np.arange(12.0)
    assert leaf_key(x) == leaf_key(x) and len(hashed) == 2  # outside a render: hashed each time
    with _cache.same_arrays():
        first = leaf_key(x)
        assert leaf_key(x) == first and len(hashed) == 3
    x[0] = 5.0
    assert leaf_key(x) != first
    from test_look_preview import _showcase

    scene = diffwash.load_scene(_showcase(tmp_path, size=32))  # every effect, on the 10k-triangle knot
    big = min(np.asarray(a).nbytes for a in (scene.mesh.vertices, scene.mesh.faces, scene.mesh.normals))

    def large_hashes():
        diffwash.render(scene)
        hashed.clear()
        diffwash.render(scene)
        return sum(n >= big for n in hashed)

    once = large_hashes()
    import contextlib

    monkeypatch.setattr(_render, "same_arrays", contextlib.nullcontext)
    assert once <= 3 < large_hashes(), once  # vertices, faces, normals once each; without the block, again per cache
