"""A minimal DNG writer for tests: an uncompressed 16-bit Bayer (RGGB) mosaic with its colour matrix.

Written with the standard library (TIFF 6.0 + Adobe DNG 1.4 tags), so that the raw-photo path is tested
without a tool that writes DNGs. The camera is taken to record linear sRGB: ColorMatrix1 is XYZ to linear
sRGB under D65, as-shot neutral (1, 1, 1).
"""

import struct

import numpy as np

from diffwash.colorimetry import SRGB_TO_XYZ

_SHORT, _LONG, _RATIONAL, _SRATIONAL, _BYTE, _ASCII = 3, 4, 5, 10, 1, 2
_SIZES = {_SHORT: 2, _LONG: 4, _RATIONAL: 8, _SRATIONAL: 8, _BYTE: 1, _ASCII: 1}


def _pack(kind, values):
    if kind == _ASCII:
        return values.encode() + b"\0"
    if kind == _BYTE:
        return bytes(values)
    if kind == _SHORT:
        return struct.pack(f"<{len(values)}H", *values)
    if kind == _LONG:
        return struct.pack(f"<{len(values)}I", *values)
    fmt = "<2i" if kind == _SRATIONAL else "<2I"
    return b"".join(struct.pack(fmt, int(round(v * 10000)), 10000) for v in values)


def write_dng(path, linear):
    """Write `linear` (H, W, 3) in [0, 1] (H and W even) as an RGGB mosaic DNG."""
    H, W, _ = linear.shape
    code = np.round(np.clip(linear, 0, 1) * 65535).astype("<u2")
    mosaic = np.empty((H, W), "<u2")
    mosaic[0::2, 0::2] = code[0::2, 0::2, 0]
    mosaic[0::2, 1::2] = code[0::2, 1::2, 1]
    mosaic[1::2, 0::2] = code[1::2, 0::2, 1]
    mosaic[1::2, 1::2] = code[1::2, 1::2, 2]
    data = mosaic.tobytes()
    xyz_to_cam = np.linalg.inv(SRGB_TO_XYZ).ravel().tolist()
    tags = [(254, _LONG, [0]), (256, _LONG, [W]), (257, _LONG, [H]), (258, _SHORT, [16]), (259, _SHORT, [1]),
            (262, _SHORT, [32803]), (271, _ASCII, "diffwash"), (272, _ASCII, "test camera"), (273, _LONG, [0]),
            (274, _SHORT, [1]), (277, _SHORT, [1]), (278, _LONG, [H]), (279, _LONG, [len(data)]),
            (284, _SHORT, [1]), (33421, _SHORT, [2, 2]), (33422, _BYTE, [0, 1, 1, 2]),
            (50706, _BYTE, [1, 4, 0, 0]), (50708, _ASCII, "diffwash test camera"), (50714, _LONG, [0]),
            (50717, _LONG, [65535]), (50721, _SRATIONAL, xyz_to_cam), (50728, _RATIONAL, [1.0, 1.0, 1.0]),
            (50778, _SHORT, [21])]  # fmt: skip
    ifd_size = 2 + 12 * len(tags) + 4
    extra_at = 8 + ifd_size
    extra, entries = b"", []
    payloads = {}
    for tag, kind, values in tags:
        raw = _pack(kind, values)
        count = len(raw) // _SIZES[kind] if kind != _ASCII else len(raw)
        if len(raw) <= 4:
            entries.append((tag, kind, count, raw.ljust(4, b"\0")))
        else:
            payloads[tag] = extra_at + len(extra)
            entries.append((tag, kind, count, struct.pack("<I", extra_at + len(extra))))
            extra += raw + (b"\0" if len(raw) % 2 else b"")
    data_at = extra_at + len(extra)
    out = [b"II*\0", struct.pack("<I", 8), struct.pack("<H", len(entries))]
    for tag, kind, count, value in entries:
        if tag == 273:
            value = struct.pack("<I", data_at)
        out.append(struct.pack("<HHI", tag, kind, count) + value)
    out.append(struct.pack("<I", 0))
    with open(path, "wb") as f:
        f.write(b"".join(out) + extra + data)
