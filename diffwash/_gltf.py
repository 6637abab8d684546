"""Binary glTF (GLB) that carries the watercolour material: the LUT as a texture, the uniforms as extras.

`mesh.glb` starts as trimesh writes it (the mesh, its normals, the look's
attributes); `with_material` then adds, without touching the geometry:

- the LUT image(s) (16-bit PNG, sRGB-encoded as `lut.png`) as glTF images in
  the binary chunk, each a texture with a linear, clamp-to-edge sampler;
- one material on every primitive, named `diffwash watercolour`, whose
  `extras.diffwash` holds what a shader needs besides the geometry: the
  uniforms' values, which texture is which LUT and how to sample it
  (docs/realtime.md, "glTF"). Its core properties are a fallback for engines
  that ignore the extras: an unlit-looking matte of the paper's colour.

glTF images are addressed with row 0 at the top (uv (0, 0) is the image's
top-left texel), which is the LUT's own convention: no flip.
"""

from __future__ import annotations

import io
import json
import struct
from typing import Any

import numpy as np
import png

__all__ = ["read_glb", "with_material", "png16"]

_MAGIC, _JSON, _BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
_LINEAR, _CLAMP_TO_EDGE = 9729, 33071


def png16(values: np.ndarray) -> bytes:
    """A 16-bit RGB PNG of `(M, N, 3)` integer values in [0, 65535] (row 0 at the top)."""
    m, n, _ = values.shape
    out = io.BytesIO()
    png.Writer(n, m, greyscale=False, bitdepth=16).write(out, np.asarray(values, np.uint16).reshape(m, n * 3))
    return out.getvalue()


def read_glb(data: bytes) -> tuple[dict[str, Any], bytes]:
    """The JSON and binary chunks of a GLB file."""
    magic, version, length = struct.unpack_from("<III", data, 0)
    if magic != _MAGIC or version != 2 or length != len(data):
        raise ValueError("not a glTF 2.0 binary (GLB) file")
    json_length, kind = struct.unpack_from("<II", data, 12)
    if kind != _JSON:
        raise ValueError("GLB: the first chunk is not JSON")
    gltf = json.loads(data[20 : 20 + json_length])
    binary = b""
    if 20 + json_length < len(data):
        bin_length, kind = struct.unpack_from("<II", data, 20 + json_length)
        if kind != _BIN:
            raise ValueError("GLB: the second chunk is not BIN")
        binary = data[28 + json_length : 28 + json_length + bin_length]
    return gltf, binary


def _pad(data: bytes, fill: bytes) -> bytes:
    return data + fill * (-len(data) % 4)


def _glb(gltf: dict[str, Any], binary: bytes) -> bytes:
    text = _pad(json.dumps(gltf, separators=(",", ":")).encode("utf-8"), b" ")
    binary = _pad(binary, b"\0")
    chunks = struct.pack("<II", len(text), _JSON) + text + struct.pack("<II", len(binary), _BIN) + binary
    return struct.pack("<III", _MAGIC, 2, 12 + len(chunks)) + chunks


def with_material(
    glb: bytes, images: dict[str, bytes], extras: dict[str, Any], *, base_colour: list[float], double_sided: bool
) -> bytes:
    """`glb` with the PNG `images` (by name) as textures and one material holding `extras`.

    `extras` becomes the material's `extras.diffwash`, with `textures`: image
    name -> glTF texture index added. `base_colour` is the fallback
    `baseColorFactor`'s RGB (linear).
    """
    gltf, binary = read_glb(glb)
    binary = bytearray(_pad(binary, b"\0"))
    for key in ("images", "textures", "samplers", "bufferViews", "materials"):
        gltf.setdefault(key, [])
    gltf["samplers"].append({"magFilter": _LINEAR, "minFilter": _LINEAR, "wrapS": _CLAMP_TO_EDGE, "wrapT": _CLAMP_TO_EDGE})
    sampler = len(gltf["samplers"]) - 1
    textures = {}
    for name, data in images.items():
        gltf["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)})
        binary += _pad(data, b"\0")
        gltf["images"].append({"name": name, "mimeType": "image/png", "bufferView": len(gltf["bufferViews"]) - 1})
        gltf["textures"].append({"name": name, "sampler": sampler, "source": len(gltf["images"]) - 1})
        textures[name] = len(gltf["textures"]) - 1
    if not gltf.get("buffers"):
        gltf["buffers"] = [{}]
    gltf["buffers"][0]["byteLength"] = len(binary)
    gltf["materials"].append({
        "name": "diffwash watercolour",
        "pbrMetallicRoughness": {"baseColorFactor": [*map(float, base_colour), 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "doubleSided": bool(double_sided),
        "extras": {"diffwash": {**extras, "textures": textures}},
    })  # fmt: skip
    material = len(gltf["materials"]) - 1
    for mesh in gltf.get("meshes", []):
        for primitive in mesh["primitives"]:
            primitive["material"] = material
    return _glb(gltf, bytes(binary))
