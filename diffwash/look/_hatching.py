r"""Hatching for a pen-and-wash unlit glaze: a tonal art map (Praun et al. 2001).

A *tonal art map* (TAM) is a set of hatch images of increasing tone, each
given at every mip level. Two nestings make it blend without artefacts:

- *tone nesting*: every stroke of a tone is also in all darker tones, so
  blending two neighbouring tones only adds strokes, never moves them;
- *resolution nesting*: every stroke of a mip level is also in all finer
  levels, drawn with the same width in texels of each level (so on screen
  the strokes keep their width as the object recedes, instead of being
  filtered into grey).

`tonal_art_map` builds one as Praun et al. do: for each level from the
coarsest, for each tone from the lightest, it starts from the union of the
strokes of the lighter tone (same level) and the coarser level (same tone),
and adds strokes until the image's mean ink coverage reaches the tone. The
lighter half of the tones hatches in one direction, the darker half adds the
cross direction, as pen-and-ink illustrators do.

Eight tones are packed in two RGBA images per level (Praun et al. pack six in
two RGB textures); the ink of a tone value `tau` in [0, 1] blends the two
nearest tones (tone 0 is blank paper): `hatch_ink`. The shaders read an atlas
of the tone pairs instead (`tam_atlas`), one fetch per projection. The texture coordinates
are a triplanar projection of object-space positions (`triplanar_weights`),
so the hatching sticks to the surface without a parametrisation, and the mip
level is computed from the pixel's footprint on the surface (`hatch_lod`),
the same number in JAX and in the shader (`textureLod`), rather than from the
screen-space derivatives a GPU would use.

**References:**

- E. Praun, H. Hoppe, M. Webb and A. Finkelstein, "Real-Time Hatching",
  SIGGRAPH 2001, secs. 3-4.
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._xla import apart

__all__ = [
    "TONES",
    "TAM_LEVELS",
    "tonal_art_map",
    "hatch_lod",
    "sample_level",
    "sample_tam",
    "tone_weights",
    "hatch_ink",
    "triplanar_weights",
    "triplanar_uv",
    "hatch_samples",
    "hatch_ink_at",
    "PackedMap",
    "pack_tam",
]

#: Tones of the map (tone 0, blank paper, is implicit): packed in two RGBA images.
TONES = 8
#: Mip levels of the map, finest first (256, 128, 64, 32, 16 texels).
TAM_LEVELS = 5
_TRIPLANAR_SHARPNESS = 4.0
_CANDIDATES = 8


def _ink_along(img: np.ndarray, stroke: tuple[float, float, float, float]) -> float:
    """The mean ink of `img` along a stroke (16 points, wrapping), to compare candidate places."""
    n = img.shape[0]
    x, y, a, ln = stroke
    s = np.linspace(-0.5, 0.5, 16) * ln
    px = np.mod(np.floor((x + s * math.cos(a)) * n), n).astype(int)
    py = np.mod(np.floor((y + s * math.sin(a)) * n), n).astype(int)
    return float(img[py, px].mean())


def _draw_stroke(img: np.ndarray, x0: float, y0: float, angle: float, length: float, width: float) -> None:
    """Add an antialiased straight stroke (coverage combined by max), wrapping around the tile."""
    n = img.shape[0]
    c, s = math.cos(angle), math.sin(angle)
    pad = width + 1.5
    half = length / 2
    ext_x = abs(c) * half + abs(s) * pad
    ext_y = abs(s) * half + abs(c) * pad
    xs = np.arange(math.floor(x0 - ext_x), math.ceil(x0 + ext_x) + 1)
    ys = np.arange(math.floor(y0 - ext_y), math.ceil(y0 + ext_y) + 1)
    X, Y = np.meshgrid(xs + 0.5, ys + 0.5)
    u = (X - x0) * c + (Y - y0) * s  # along the stroke
    v = -(X - x0) * s + (Y - y0) * c  # across
    taper = np.clip(half - np.abs(u), 0, 1)  # antialiased ends
    across = np.clip(width / 2 + 0.5 - np.abs(v), 0, 1)  # antialiased sides
    cov = taper * across
    r = np.mod(ys, n)[:, None]
    q = np.mod(xs, n)[None, :]
    np.maximum.at(img, (np.broadcast_to(r, cov.shape), np.broadcast_to(q, cov.shape)), cov)


def tonal_art_map(
    *,
    size: int = 256,
    levels: int = TAM_LEVELS,
    tones: int = TONES,
    max_ink: float = 0.8,
    width: float = 1.2,
    length: float = 0.45,
    angle: float = math.radians(60.0),
    seed: int = 0,
) -> list[np.ndarray]:
    """A tonal art map: `levels` mip levels of `tones` nested hatch images.

    **Arguments:**

    - `size`: the finest level's side (a power of two); level `l` is `size / 2^l`.
    - `levels`: how many levels (finest first).
    - `tones`: how many tones; tone `k` (1-based) has mean ink `k / tones * max_ink`.
    - `width`: stroke width, in texels of every level.
    - `length`: stroke length, as a fraction of the tile.
    - `angle`: the hatching direction (radians); the darker half of the tones
      adds strokes at `angle + 90 degrees`.
    - `seed`: the random seed.

    **Returns:**

    A list (finest first) of `(n_l, n_l, tones)` float32 ink coverages in [0, 1].
    """
    rng = np.random.default_rng(seed)
    sizes = [size >> l for l in range(levels)]
    if sizes[-1] < 4 or size & (size - 1):
        raise ValueError(f"size must be a power of two with {levels} levels of at least 4 texels, got {size}")
    targets = [k / tones * max_ink for k in range(1, tones + 1)]
    # strokes[t] holds every stroke (as fractions of the tile) added for tone <= t at any level so far.
    strokes: list[list[tuple[float, float, float, float]]] = [[] for _ in range(tones)]
    out = [np.zeros((n, n, tones), np.float32) for n in sizes]
    for li in range(levels - 1, -1, -1):  # coarsest first
        n = sizes[li]
        img = np.zeros((n, n))
        for t in range(tones):
            for st in strokes[t]:  # strokes of lighter tones and coarser levels
                _draw_stroke(img, st[0] * n, st[1] * n, st[2], st[3] * n, width)
            cross = t >= tones // 2
            tries = 0
            while img.mean() < targets[t] and tries < 20000:
                tries += 1
                a = angle + (math.pi / 2 if cross and rng.random() < 0.5 else 0.0) + rng.normal(0, 0.05)
                # Of a few candidate places, the one where the image is lightest (Praun et al. pick the
                # candidate that best evens out the tone), so strokes spread out instead of clumping.
                cands = [(rng.random(), rng.random(), a, length * rng.uniform(0.7, 1.0)) for _ in range(_CANDIDATES)]
                st = min(cands, key=lambda c: _ink_along(img, c))
                _draw_stroke(img, st[0] * n, st[1] * n, st[2], st[3] * n, width)
                for later in range(t, tones):
                    strokes[later].append(st)
            out[li][..., t] = img
    return out


def hatch_lod(pixel_size: Float[ArrayLike, "*b"], texels_per_unit: float, levels: int = TAM_LEVELS) -> Float[Array, "*b"]:
    """The mip level for a pixel covering `pixel_size` object units: `log2(pixel_size * texels_per_unit)`, in [0, levels - 1]."""
    x = jnp.asarray(pixel_size) * texels_per_unit
    ok = x > 0
    lod = jnp.log2(jnp.where(ok, x, 1.0))
    return jnp.clip(jnp.where(ok, lod, 0.0), 0.0, levels - 1.0)


def sample_level(image: Float[ArrayLike, "n n C"], uv: Float[ArrayLike, "*b 2"]) -> Float[Array, "*b C"]:
    """Bilinear sample with wrap-around (GL_REPEAT) at `uv` (texture coordinates, `[0, 1)` per tile)."""
    image = jnp.asarray(image)
    n = image.shape[0]
    t = jnp.asarray(uv) * n - 0.5
    i0 = jnp.floor(t)
    f = t - i0
    i0 = i0.astype(jnp.int32)
    x0, y0 = jnp.mod(i0[..., 0], n), jnp.mod(i0[..., 1], n)
    x1, y1 = jnp.mod(x0 + 1, n), jnp.mod(y0 + 1, n)
    fx, fy = f[..., 0:1], f[..., 1:2]
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def _sample_packed(flat: Array, offsets: Array, sizes: Array, uv: Array, level: Array) -> Array:
    """Bilinear sample with wrap-around of the square level `level` (per point) of levels packed in `flat`."""
    n = sizes[level]
    t = uv * n[..., None].astype(uv.dtype) - 0.5
    i0 = jnp.floor(t)
    f = t - i0
    i0 = i0.astype(jnp.int32)
    x0, y0 = jnp.mod(i0[..., 0], n), jnp.mod(i0[..., 1], n)
    x1, y1 = jnp.mod(x0 + 1, n), jnp.mod(y0 + 1, n)
    base = offsets[level]
    fx, fy = f[..., 0:1], f[..., 1:2]
    top = flat[base + y0 * n + x0] * (1 - fx) + flat[base + y0 * n + x1] * fx
    bottom = flat[base + y1 * n + x0] * (1 - fx) + flat[base + y1 * n + x1] * fx
    return top * (1 - fy) + bottom * fy


def sample_tam(tam: list, uv: Float[ArrayLike, "*b 2"], lod: Float[ArrayLike, "*b"]) -> Float[Array, "*b C"]:
    """Trilinear sample of the map at `uv` and mip level `lod` (as `textureLod` with LINEAR_MIPMAP_LINEAR).

    Only the two levels around `lod` are read (the levels are packed into one
    table and indexed per point): 8 texels per point, whatever the level count.
    """
    lod = jnp.asarray(lod)
    uv = jnp.asarray(uv)
    top = len(tam) - 1
    sizes_np = np.array([np.shape(level)[0] for level in tam], np.int32)
    offsets_np = np.concatenate([[0], np.cumsum(sizes_np.astype(np.int64) ** 2)[:-1]]).astype(np.int32)
    flat = jnp.concatenate([jnp.reshape(jnp.asarray(level), (-1, jnp.shape(level)[-1])) for level in tam], axis=0)
    flat = jax.lax.optimization_barrier(flat)  # else XLA fuses the concatenation into every gather
    sizes, offsets = jnp.asarray(sizes_np), jnp.asarray(offsets_np)
    l0 = jnp.clip(jnp.floor(lod), 0, top)
    f = (jnp.clip(lod, 0, top) - l0)[..., None]
    i0 = l0.astype(jnp.int32)
    i1 = jnp.minimum(i0 + 1, top)
    a = _sample_packed(flat, offsets, sizes, uv, i0)
    b = _sample_packed(flat, offsets, sizes, uv, i1)
    return a * (1 - f) + b * f


def tone_weights(tau: Float[ArrayLike, "*b"], tones: int = TONES) -> Float[Array, "*b T"]:
    """Weights of the `tones` images for a tone value `tau` in [0, 1]: the two nearest tones, linearly.

    Tone `k` (1-based) sits at `k / tones`; tone 0 is blank paper (no image).
    Differentiable in `tau` (piecewise linear).
    """
    x = jnp.clip(jnp.asarray(tau), 0.0, 1.0) * tones
    k = jnp.arange(1, tones + 1, dtype=x.dtype)
    return jnp.clip(1 - jnp.abs(x[..., None] - k), 0.0, 1.0)


def hatch_ink(samples: Float[ArrayLike, "*b T"], tau: Float[ArrayLike, "*b"]) -> Float[Array, "*b"]:
    """The ink at tone `tau`: the map's samples (all tones) blended by `tone_weights`."""
    samples = jnp.asarray(samples)
    return jnp.sum(samples * tone_weights(tau, samples.shape[-1]), axis=-1)


def triplanar_weights(normal: Float[ArrayLike, "*b 3"]) -> Float[Array, "*b 3"]:
    """Blend weights of the three axis projections: `|n_i|^4`, normalised (sharp, so strokes rarely mix)."""
    n2 = jnp.square(jnp.asarray(normal))
    a = n2 * n2 if _TRIPLANAR_SHARPNESS == 4.0 else jnp.abs(jnp.asarray(normal)) ** _TRIPLANAR_SHARPNESS  # |n|^4 without pow
    total = a[..., 0:1] + a[..., 1:2] + a[..., 2:3]  # (not jnp.sum: XLA's CPU reduction of 3 is slow)
    return a / jnp.maximum(total, 1e-12)


def atlas_pad(levels: int = TAM_LEVELS) -> int:
    """Rows of wrap padding above and below each tile of `tam_atlas` at level 0 (halved at each level, 1 at the last)."""
    return 2 ** (levels - 1)


def tam_atlas(tam: list, tones: int = TONES) -> list[np.ndarray]:
    """The map as the shaders sample it: one RG image per level, `tones` tiles stacked in rows.

    Tile `k` holds the ink of the two tones `hatch_ink` blends for a tone value
    in `[k, k + 1) / tones`: channel R tone `k` (blank paper, 0, for `k = 0`),
    G tone `k + 1` (the map's channels `k - 1` and `k`). So one bilinear fetch
    per projection reads both tones (the shader picks the tile by its rows),
    where the two RGBA images of every tone would need two. Each tile is padded
    above and below by `atlas_pad(levels) >> level` rows copied from its other
    end, so filtering at a tile's edge reads what `GL_REPEAT` would; with the
    padding halving at each level, level `l` is exactly half of level `l - 1`,
    and the same texture coordinate addresses the same point of the tile at
    every level. Shape of level `l`: `(tones * (n_l + 2 p_l), n_l, 2)`.
    """
    levels = [np.asarray(level, np.float32) for level in tam]
    pad0 = atlas_pad(len(levels))
    out = []
    for index, level in enumerate(levels):
        n, p = level.shape[0], pad0 >> index
        below = np.concatenate([np.zeros(level.shape[:2] + (1,), np.float32), level[..., : tones - 1]], axis=-1)
        tiles = []
        for k in range(tones):
            tile = np.stack([below[..., k], level[..., k]], axis=-1)
            tiles.append(np.concatenate([tile[n - p :], tile, tile[:p]], axis=0))
        out.append(np.ascontiguousarray(np.concatenate(tiles, axis=0)))
    return out


def triplanar_uv(P: Float[ArrayLike, "*b 3"], scale: float, size: int = 256) -> tuple[Array, Array, Array]:
    """Texture coordinates of the three projections (x: `(y, z)`, y: `(z, x)`, z: `(x, y)`) at `scale` texels per unit."""
    q = jnp.asarray(P) * (scale / size)
    return q[..., 1:3], jnp.stack([q[..., 2], q[..., 0]], axis=-1), q[..., 0:2]


def hatch_samples(
    tam: list, P: Float[ArrayLike, "*b 3"], N: Float[ArrayLike, "*b 3"], pixel_size: Float[ArrayLike, "*b"], scale: float
) -> Float[Array, "*b T"]:
    """The map's ink of every tone at object points `P` with normals `N`: triplanar, explicit LOD.

    `pixel_size`: each pixel's footprint in object units (e.g. eye depth times
    `2 tan(fov_y / 2) / height`); `scale`: texels of level 0 per object unit.
    `hatch_ink(samples, tau)` then blends the two tones nearest `tau` (the
    reference that `hatch_ink_at`, and the shaders' `look_hatch_ink`, are held to).
    """
    lod = hatch_lod(pixel_size, scale, len(tam))
    w = triplanar_weights(N)
    size = tam[0].shape[0]
    out = 0.0
    for k, uv in enumerate(triplanar_uv(P, scale, size)):
        out = out + w[..., k : k + 1] * sample_tam(tam, uv, lod)
    return out


class PackedMap(eqx.Module):
    """A tonal art map's levels in one flat table, as `hatch_ink_at` reads it (`pack_tam`).

    **Fields:** `table` (every level's texels in turn, row-major, the tones
    last: `(sum n_l^2 * tones,)`), `sizes` (each level's side, a power of
    two, finest first), `tones`.
    """

    table: Any
    sizes: tuple[int, ...] = eqx.field(static=True)
    tones: int = eqx.field(static=True)


def pack_tam(tam: list) -> PackedMap:
    """The `PackedMap` of a tonal art map's levels (NumPy in, NumPy out: build it once, outside a kernel)."""
    sizes = tuple(int(np.shape(level)[0]) for level in tam)
    if any(n & (n - 1) for n in sizes):
        raise ValueError(f"the map's levels must be powers of two, got sides {list(sizes)}")
    xp = np if all(isinstance(level, np.ndarray) for level in tam) else jnp
    table = xp.concatenate([xp.reshape(xp.asarray(level), (-1,)) for level in tam])
    return PackedMap(table=table, sizes=sizes, tones=int(np.shape(tam[0])[-1]))


def hatch_ink_at(
    tam: list | PackedMap,
    P: Float[ArrayLike, "*b 3"],
    N: Float[ArrayLike, "*b 3"],
    pixel_size: Float[ArrayLike, "*b"],
    scale: float,
    tau: Float[ArrayLike, "*b"],
) -> Float[Array, "*b"]:
    """`hatch_ink(hatch_samples(tam, P, N, pixel_size, scale), tau)`, reading only the two tones it blends.

    The same number (the tone weights are zero but for the two tones around
    `tau`, and sampling is linear in the texels), at a quarter of the texel
    reads: 48 scalar reads per point (3 projections, 2 levels, 4 bilinear
    taps, 2 tones) instead of 192. Gathers dominate the look's cost on a CPU,
    so this is the form the renderer uses; `hatch_samples` is kept for the
    shader's twin test. Differentiable in `P`, `N`, `pixel_size` and `tau`
    (piecewise linear in `tau`, as `tone_weights`).
    """
    packed = tam if isinstance(tam, PackedMap) else pack_tam(tam)
    flat, tones, sizes_np = jnp.asarray(packed.table), packed.tones, np.asarray(packed.sizes, np.int32)
    offsets_np = np.concatenate([[0], np.cumsum(sizes_np.astype(np.int64) ** 2)[:-1]]).astype(np.int32)
    tau = jnp.asarray(tau)
    lod = hatch_lod(pixel_size, scale, len(sizes_np))
    w = triplanar_weights(N)
    top = len(sizes_np) - 1
    l0 = jnp.clip(jnp.floor(lod), 0, top)
    fl = jnp.clip(lod, 0, top) - l0
    level0 = l0.astype(jnp.int32)
    level1 = jnp.minimum(level0 + 1, top)
    # Tone k (1-based, weight 1 - g) and k + 1 (weight g) around x = tau * tones; tone 0 is blank paper.
    x = jnp.clip(tau, 0.0, 1.0) * tones
    k = jnp.clip(jnp.floor(x), 0, tones - 1)
    g = x - k
    k = k.astype(jnp.int32)
    ink_k = jnp.where(k >= 1, 1 - g, 0.0)  # weight of channel k - 1 (none for blank paper)
    first, second = jnp.maximum(k - 1, 0), k
    # The reads apart: XLA would otherwise fuse what makes their inputs (the tone, the shadow lookups before
    # it, the level) into each of the 48 reads and compute it again there (several times slower).
    sizes, offsets = jnp.asarray(sizes_np), jnp.asarray(offsets_np)

    def level(flat: Array, uv: Array, li: Array | int, first: Array, second: Array, ink_k: Array, g: Array) -> Array:
        # `li` per point, or the finest level's 0 for every point (its side and offset then constants, not reads).
        n, offset = (sizes[li], offsets[li]) if isinstance(li, jax.Array) else (int(sizes_np[li]), int(offsets_np[li]))
        mask = n - 1  # wrap-around (GL_REPEAT): sides are powers of two
        t = uv * (n[..., None].astype(uv.dtype) if isinstance(n, jax.Array) else n) - 0.5
        i0 = jnp.floor(t)
        f = t - i0
        i0 = i0.astype(jnp.int32)
        x0, y0 = i0[..., 0] & mask, i0[..., 1] & mask
        x1, y1 = (x0 + 1) & mask, (y0 + 1) & mask
        fx, fy = f[..., 0], f[..., 1]
        out = 0.0
        for row, wy in ((y0, 1 - fy), (y1, fy)):
            for col, wx in ((x0, 1 - fx), (x1, fx)):
                texel = (offset + row * n + col) * tones
                out = out + (wy * wx) * (flat[texel + first] * ink_k + flat[texel + second] * g)
        return out

    def reads(flat, P, w, fl, level0, level1, *tone):
        ink = 0.0
        for p, uv in enumerate(triplanar_uv(P, scale, int(sizes_np[0]))):
            ink = ink + w[..., p] * (level(flat, uv, level0, *tone) * (1 - fl) + level(flat, uv, level1, *tone) * fl)
        return ink

    def reads_finest(flat, P, w, fl, level0, level1, *tone):  # every point magnified: level 0 alone, weight 1
        ink = 0.0
        for p, uv in enumerate(triplanar_uv(P, scale, int(sizes_np[0]))):
            ink = ink + w[..., p] * level(flat, uv, 0, *tone)
        return ink

    # Where the map is magnified at every point (the level of detail clamped at 0, as in a close-up or the
    # showcase at 512^2), the second level's weight is 0 everywhere: read one level, half the reads, the same
    # value and the same gradient (the clamp passes none to the level's weight).
    args = (flat, jnp.asarray(P), w, fl, level0, level1, first, second, ink_k, g)
    return jax.lax.cond(jnp.any(lod > 0), lambda *a: apart(reads, *a), lambda *a: apart(reads_finest, *a), *args)
