"""Image and JSON input/output: bit depths, EXIF orientation, atomic writes."""

import json

import numpy as np
import pytest
from PIL import Image, ImageOps

from diffwash import DiffwashError
from diffwash._io import atomic_path, read_image, read_json, write_json, write_png


def test_png16_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    img = rng.uniform(0, 1, (7, 9, 3))
    write_png(tmp_path / "a.png", img, bits=16)
    back, bits = read_image(tmp_path / "a.png")
    assert bits == 16 and back.shape == (7, 9, 3)
    np.testing.assert_allclose(back, img, atol=0.5 / 65535 + 1e-12)


def test_png8_round_trip_and_greyscale_alpha(tmp_path):
    img = np.linspace(0, 1, 4 * 5 * 4).reshape(4, 5, 4)
    write_png(tmp_path / "a.png", img, bits=8)
    back, bits = read_image(tmp_path / "a.png", opaque=False)
    assert bits == 8 and back.shape == (4, 5, 3)  # alpha dropped
    np.testing.assert_allclose(back, img[..., :3], atol=0.5 / 255 + 1e-12)
    write_png(tmp_path / "g.png", img[..., 0], bits=8)
    back, _ = read_image(tmp_path / "g.png", colour=False)
    assert back.shape == (4, 5, 3) and np.allclose(back[..., 0], back[..., 2])


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_is_applied_like_pillow(tmp_path, orientation):
    rng = np.random.default_rng(orientation)
    arr = (rng.uniform(0, 255, (6, 10, 3))).astype(np.uint8)
    exif = Image.Exif()
    exif[0x0112] = orientation
    for ext in ("png", "jpg"):
        path = tmp_path / f"o.{ext}"
        Image.fromarray(arr).save(path, exif=exif.tobytes(), **({"quality": 100} if ext == "jpg" else {}))
        with Image.open(path) as im:
            expected = np.asarray(ImageOps.exif_transpose(im).convert("RGB"), np.float64) / 255
        got, _ = read_image(path)
        assert got.shape == expected.shape
        np.testing.assert_allclose(got, expected, atol=1e-12)


def test_unreadable_images_are_clear_errors(tmp_path):
    (tmp_path / "x.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    with pytest.raises(DiffwashError, match=r"x\.png: not a readable PNG"):
        read_image(tmp_path / "x.png")
    (tmp_path / "y.jpg").write_text("hello")
    with pytest.raises(DiffwashError, match=r"y\.jpg: is not an image diffwash reads"):
        read_image(tmp_path / "y.jpg")
    with pytest.raises(DiffwashError, match=r"z\.png: no such image file"):
        read_image(tmp_path / "z.png")


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]
    with pytest.raises(ValueError):
        write_json(target, {"x": float("nan")})  # refused before anything is written
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_writing_into_a_missing_or_readonly_folder(tmp_path):
    with pytest.raises(DiffwashError, match="output folder does not exist"):
        write_json(tmp_path / "nope" / "a.json", {})
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        import os

        if os.access(ro, os.W_OK):  # running as root: permissions do not bind
            return
        with pytest.raises(DiffwashError, match="cannot write here"):
            write_json(ro / "a.json", {})
    finally:
        ro.chmod(0o700)


def test_read_json_errors(tmp_path):
    with pytest.raises(DiffwashError, match="no such file"):
        read_json(tmp_path / "missing.json")
    (tmp_path / "b.json").write_text('{"a": 1,}')
    with pytest.raises(DiffwashError, match=r"b\.json: malformed JSON at line 1 column 9"):
        read_json(tmp_path / "b.json")
    (tmp_path / "ok.json").write_text(json.dumps({"a": [1, 2]}))
    assert read_json(tmp_path / "ok.json") == {"a": [1, 2]}
