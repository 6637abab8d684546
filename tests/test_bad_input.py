"""Bad input refused, never half-handled, through the command line's entry point (`diffwash.cli.main` in this
process, or `python -m diffwash`): exit status 2 (1 when the work failed, e.g. a full disk), one line naming the
file and the field, inputs intact, nothing left behind."""

import builtins
import errno
import io
import json
import os
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, ROOT
from PIL import Image

import diffwash
from diffwash.swatchcard import IDEAL, make_swatch_card, save_swatch_card

SPHERE = DATA / "meshes" / "sphere.ply"


def refused(result, *needles, status=2):
    """The command failed with `status` and said so in one line holding each of `needles`."""
    code, _, err = result
    assert code == status, err
    assert err.startswith("diffwash") and err.count("\n") == 1 and "Traceback" not in err, err
    for n in needles:
        assert n in err, err


def snapshot(folder):
    """Every file under `folder` with its bytes: what a refused command must leave as it was."""
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def write_scene(folder, name="scene.json", size=16, **changes):
    scene = {
        "mesh": str(SPHERE), "image": {"width": size, "height": size},
        "camera": {"eye": [0, 0, 3.5], "target": [0, 0, 0]}, "light": {"direction": [-1, 1, 1]},
        "wash": {"pigment": "Cadmium Yellow"}, "unlit": {"pigment": "Phthalo Green"}, **changes,
    }  # fmt: skip
    (folder / name).write_text(json.dumps(scene))
    return folder / name


@pytest.fixture
def target(tmp_path):
    """scene.json (16 x 16 pixels) and target.png, the scene rendered with a higher gain."""
    from diffwash import colorimetry
    from diffwash._io import write_png

    write_scene(tmp_path, "truth.json", gain=0.7)
    img = np.asarray(diffwash.render(diffwash.load_scene(tmp_path / "truth.json")))
    write_png(tmp_path / "target.png", np.asarray(colorimetry.srgb_encode(np.clip(img, 0, 1))))
    return write_scene(tmp_path)


@pytest.fixture
def card(tmp_path):
    """An ideal swatch-card photo (card.png) and its layout (card.json)."""
    save_swatch_card(make_swatch_card(diffwash.pigments.load("Cadmium Red"), coats=(1, 2), effects=IDEAL),
                     tmp_path / "card.png")  # fmt: skip
    return tmp_path / "card.png", tmp_path / "card.json"


# ---------------------------------------------------------------------------------------------------------------
# Images: sizes checked from the header, before decoding; greyscale and transparent photos refused.


def png_bomb(path, side=30000):
    """A valid PNG of side x side pixels (1-bit palette, red and green) in about 100 kB: decoded, 2.7 GB of RGB."""
    chunk = lambda k, d: struct.pack(">I", len(d)) + k + d + struct.pack(">I", zlib.crc32(k + d))  # noqa: E731
    z = zlib.compressobj(9)
    row = b"\0" * (1 + (side + 7) // 8)
    idat = b"".join(z.compress(row * 1000) for _ in range(side // 1000)) + z.flush()
    head = chunk(b"IHDR", struct.pack(">IIBBBBB", side, side, 1, 3, 0, 0, 0)) + chunk(b"PLTE", b"\xff\0\0\0\xff\0")
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + head + chunk(b"IDAT", idat) + chunk(b"IEND", b""))
    return path


#: Runs `python -m diffwash ARGS` (argv[2:]) and, at its exit, writes its own peak resident memory in kB to argv[1]:
#: the kernel's high-water mark of this process's memory since its exec (VmHWM), not `ru_maxrss`. A child's
#: `ru_maxrss` (`wait4`, `getrusage`) also holds the high-water mark of the process it was spawned from (Linux keeps
#: the old memory's peak across exec, and `subprocess` spawns by vfork, with the parent's memory), so beside heavy
#: tests, in a pytest worker that once peaked at 900 MB, a 290 MB command read 900 MB.
_MEASURED = """
import atexit, resource, runpy, sys
def report(path=sys.argv[1]):
    try:
        with open("/proc/self/status") as f:
            kb = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
    except (OSError, StopIteration):  # no /proc (macOS): the usage figure, an upper bound
        kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // (1024 if sys.platform == "darwin" else 1)
    with open(path, "w") as f:
        f.write(str(kb))
atexit.register(report)
sys.argv = ["diffwash", *sys.argv[2:]]
runpy.run_module("diffwash", run_name="__main__", alter_sys=True)
"""


def peak_rss_of(args, cwd, timeout=120):
    """Run `python -m diffwash ARGS` in `cwd`: (status, stderr, its own peak resident memory in MB)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "DIFFWASH_CACHE_DIR": "off"}
    report = cwd / "peak_rss.txt"
    report.unlink(missing_ok=True)
    p = subprocess.run([sys.executable, "-c", _MEASURED, report, *map(str, args)], cwd=cwd, env=env,
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, timeout=timeout, text=True)  # fmt: skip
    return p.returncode, p.stderr, int(report.read_text()) / 1024


def test_decompression_bomb_is_refused_from_its_header_with_little_memory(tmp_path):
    bomb = png_bomb(tmp_path / "bomb.png")
    assert bomb.stat().st_size < 1_000_000
    (tmp_path / "layout.json").write_text(json.dumps({"paper": {"box": [0, 0, 9, 9]},
                                                      "patches": [{"box": [9, 9, 19, 19], "coats": 1, "ground": "paper"}]}))  # fmt: skip
    write_scene(tmp_path, size=64)
    for args in (["fit-swatch", "bomb.png", "--layout", "layout.json", "-o", "p.json"],
                 ["fit-image", "bomb.png", "--scene", "scene.json", "--fit", "gain", "-o", "f.json"]):  # fmt: skip
        status, err, mb = peak_rss_of(args, tmp_path)
        assert status == 2 and err.count("\n") == 1, err
        assert "bomb.png: is 30000x30000 = 900,000,000 pixels by its header, over the limit" in err
        assert "DIFFWASH_MAX_IMAGE_PIXELS" in err and "--max-image-pixels" in err
        assert mb < 800, f"{args[0]} peaked at {mb:.0f} MB"  # decoding would take gigabytes
    assert not (tmp_path / "p.json").exists() and not (tmp_path / "f.json").exists()


def test_the_image_limit_is_configurable(cli, card, tmp_path, monkeypatch):
    photo, layout = card
    w, h = opened(photo).size
    # A layout whose one fault shows only once the photo is read (a box outside it).
    bad = json.loads(Path(layout).read_text())
    bad["patches"] = bad["patches"][:1]
    bad["patches"][0]["box"] = [0, 0, w + 10, 5]
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    small = str(w * h - 1)
    refused(cli("fit-swatch", photo.name, "--layout", "bad.json", "-o", "p.json", "--max-image-pixels", small),
            f"card.png: is {w}x{h}", f"over the limit of {w * h - 1:,}")  # fmt: skip
    # Raised (or at the default), the photo is read, and the next problem is the layout's.
    refused(cli("fit-swatch", photo.name, "--layout", "bad.json", "-o", "p.json", "--max-image-pixels", str(w * h)),
            f"bad.json: patches[0].box: [0, 0, {w + 10}, 5] lies outside the {w}x{h} photo")  # fmt: skip
    monkeypatch.setenv("DIFFWASH_MAX_IMAGE_PIXELS", small)
    refused(cli("fit-swatch", photo.name, "--layout", "bad.json", "-o", "p.json"), "card.png: is", "over the limit")
    monkeypatch.setenv("DIFFWASH_MAX_IMAGE_PIXELS", "lots")
    refused(cli("fit-swatch", photo.name, "--layout", "bad.json", "-o", "p.json"),
            "DIFFWASH_MAX_IMAGE_PIXELS: must be a whole number of pixels >= 1, got 'lots'")  # fmt: skip
    refused(cli("fit-swatch", photo.name, "--layout", "bad.json", "-o", "p.json", "--max-image-pixels", "0"),
            "--max-image-pixels: must be a whole number of pixels")  # fmt: skip


def opened(path):
    """An image file's pixels, the file closed."""
    with Image.open(path) as im:
        return im.copy()


def _greyscale(src, dst):
    opened(src).convert("L").save(dst)


def _grey_rgb(src, dst):
    opened(src).convert("L").convert("RGB").save(dst)


def _transparent(src, dst):
    im = opened(src).convert("RGBA")
    im.putalpha(0)
    im.save(dst)


def _partly_transparent(src, dst):
    a = np.asarray(opened(src).convert("RGBA")).copy()
    a[: a.shape[0] // 4, :, 3] = 0
    Image.fromarray(a).save(dst)


@pytest.mark.parametrize("make, needle", [
    (_greyscale, "is a greyscale image"),
    (_grey_rgb, "is a greyscale image"),
    (_transparent, "is fully transparent (alpha 0 everywhere)"),
    (_partly_transparent, "is transparent or translucent in 2"),
])  # fmt: skip
def test_greyscale_and_transparent_photos_are_refused(cli, card, tmp_path, make, needle):
    photo, layout = card
    make(photo, tmp_path / "odd.png")
    refused(cli("fit-swatch", "odd.png", "--layout", layout.name, "-o", "p.json"), f"odd.png: {needle}")
    write_scene(tmp_path)
    refused(cli("fit-image", "odd.png", "--scene", "scene.json", "--fit", "gain", "-o", "f.json"), f"odd.png: {needle}")
    assert not (tmp_path / "p.json").exists() and not (tmp_path / "f.json").exists()


# ---------------------------------------------------------------------------------------------------------------
# Outputs: never over an input, never two outputs in one file, and the bytes the extension names.


def _inputs(tmp_path):
    write_scene(tmp_path, wash={"pigment": "pigment.json"})
    (tmp_path / "pigment.json").write_text(json.dumps({"name": "Rose", "K": [0.2, 1.4, 0.5], "S": [0.05, 0, 0.03]}))
    (tmp_path / "lut.json").write_text("{}")
    (tmp_path / "lut.png").write_bytes(b"a LUT")
    (tmp_path / "table.csv").write_text("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nA,1,paper,200,100,50\n")
    (tmp_path / "old").mkdir()
    write_scene(tmp_path / "old", "scene.json")
    (tmp_path / "old" / "viewer.html").write_text("a previous export")


@pytest.mark.parametrize("args, field, victim", [
    (["fit-swatch", "card.png", "--layout", "card.json", "-o", "card.json"], "--output", "card.json"),
    (["fit-swatch", "card.png", "--layout", "card.json", "-o", "p.json", "--report", "card.png"], "--report", "card.png"),
    (["swatch-card", "Cadmium Red", "-o", "x.png", "--layout", "x.png"], "--output", "x.png"),
    (["swatch-card", "pigment.json", "-o", "x.png", "--layout", "pigment.json"], "--layout", "pigment.json"),
    (["render", "scene.json", "-o", "scene.json"], "--output", "scene.json"),
    (["bake", "scene.json", "-o", "scene.png"], "--output (sidecar)", "scene.json"),
    (["fit-image", "card.png", "--scene", "scene.json", "--fit", "gain", "-o", "scene.json"], "--output", "scene.json"),
    (["fit-image", "card.png", "--scene", "scene.json", "--fit", "gain", "-o", "pigment.json"], "--output",
     "pigment.json"),
    (["preview", "scene.json", "--lut", "lut.json", "-o", "lut.png"], "--output", "lut.png"),
    (["export", "old/scene.json", "-o", "old", "--overwrite"], "--output", "old"),
])  # fmt: skip
def test_outputs_that_name_an_input_are_refused_before_any_work(cli, card, tmp_path, args, field, victim):
    _inputs(tmp_path)
    before = snapshot(tmp_path)
    code, out, err = cli(*args)
    refused((code, out, err), f"{field}:")
    assert victim in err and ("input" in err or "also the" in err), err
    assert snapshot(tmp_path) == before  # the inputs intact, nothing written


@pytest.mark.parametrize("args, output", [
    (["swatches", "Cadmium Red", "-o", "chart.jpg"], "chart.jpg"),
    (["swatches", "Cadmium Red", "-o", "chart.JPEG"], "chart.JPEG"),
    (["render", "scene.json", "-o", "frame.jpg"], "frame.jpg"),
    (["preview", "scene.json", "-o", "frame.jpg", "--lut-size", "8"], "frame.jpg"),
    (["swatch-card", "Cadmium Red", "-o", "card.jpeg", "--ideal"], "card.jpeg"),
])  # fmt: skip
def test_a_jpg_name_gets_jpeg_bytes(cli, tmp_path, args, output):
    write_scene(tmp_path)
    code, _, err = cli(*args)
    assert code == 0, err
    with Image.open(tmp_path / output) as im:
        assert im.format == "JPEG"


@pytest.mark.parametrize("args, field", [
    (["swatches", "Cadmium Red", "-o", "chart.gif"], "--output"),
    (["swatches", "Cadmium Red", "-o", "chart"], "--output"),
    (["preview", "scene.json", "-o", "frame.webp"], "--output"),
    (["render", "scene.json", "-o", "frame.jpg", "--bits", "16"], "--output"),
    (["swatch-card", "Cadmium Red", "-o", "card.tif"], "--output"),
    (["swatch-card", "Cadmium Red", "-o", "card.jpg", "--bits", "16"], "--output"),
])  # fmt: skip
def test_an_image_extension_that_is_not_its_format_is_refused(cli, tmp_path, args, field):
    write_scene(tmp_path)
    before = snapshot(tmp_path)
    refused(cli(*args), f"{field}:")
    assert snapshot(tmp_path) == before


# ---------------------------------------------------------------------------------------------------------------
# A full disk: every writer fails in one line (exit 1) and leaves nothing, not even part of the demo.


class FullDisk:
    """Files opened for writing under `root` hold `free` bytes in all; then a write fails as on a full disk (ENOSPC).

    Installed as `open` (builtins and io): Python, pathlib, Pillow, matplotlib, pypng and numpy write through it.
    """

    def __init__(self, root, free=0):
        self.root, self.free, self.real = Path(root).resolve(), free, builtins.open

    def open(self, file, mode="r", *args, **kwargs):
        f = self.real(file, mode, *args, **kwargs)
        writing = isinstance(file, (str, os.PathLike)) and any(c in mode for c in "wax+")
        if writing and Path(os.path.abspath(file)).resolve().is_relative_to(self.root):
            return _Limited(f, self)
        return f


class _Limited:
    def __init__(self, f, disk):
        self._f, self._disk = f, disk

    def write(self, data):
        n = memoryview(data).nbytes if not isinstance(data, str) else len(data.encode())
        if n > self._disk.free:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), self._f.name)
        self._disk.free -= n
        return self._f.write(data)

    def fileno(self):  # no writing around us through the descriptor
        raise io.UnsupportedOperation("fileno")

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


@pytest.fixture
def full_disk(tmp_path, monkeypatch):
    def install(free=0):
        disk = FullDisk(tmp_path, free)
        monkeypatch.setattr(builtins, "open", disk.open)
        monkeypatch.setattr(io, "open", disk.open)

    return install


@pytest.mark.parametrize("args", [
    ["render", "scene.json", "-o", "out.png"],
    ["render", "scene.json", "-o", "out.jpg"],
    ["bake", "scene.json", "-o", "out.png", "--size", "8"],
    ["bake", "scene.json", "-o", "out.npy", "--size", "8"],
    ["export", "scene.json", "-o", "out", "--size", "8"],
    ["preview", "scene.json", "-o", "out.png", "--lut-size", "8"],
    ["swatches", "Cadmium Red", "-o", "out.png"],
    ["swatch-card", "Cadmium Red", "-o", "out.jpg"],
    ["fit-swatch", "card.png", "--layout", "card.json", "-o", "out.json", "--max-steps", "3", "--allow-unconverged"],
    ["fit-swatch", "--table", "table.csv", "-o", "out.json", "--max-steps", "3", "--allow-unconverged"],
    ["fit-image", "target.png", "--scene", "scene.json", "--fit", "gain", "-o", "out.json", "--max-steps", "1",
     "--allow-unconverged", "--quiet"],
])  # fmt: skip
def test_a_full_disk_is_one_line_and_leaves_nothing(cli, card, target, tmp_path, full_disk, args):
    _inputs(tmp_path)
    before = snapshot(tmp_path)
    full_disk(free=0)
    refused(cli(*args), "out", "cannot write: No space left on device; nothing was written", status=1)
    assert snapshot(tmp_path) == before
    assert not list(tmp_path.rglob("*.part*"))


@pytest.mark.parametrize("args", [
    ["fit-swatch", "card.png", "--layout", "card.json", "-o", "out.json", "--report", "report.png", "--max-steps",
     "3", "--allow-unconverged"],
    ["fit-image", "target.png", "--scene", "scene.json", "--fit", "gain", "-o", "out.json", "--max-steps", "1",
     "--allow-unconverged", "--quiet", "--report", "report.png"],
])  # fmt: skip
def test_a_report_that_does_not_fit_on_the_disk_takes_the_fit_with_it(cli, card, target, tmp_path, full_disk, args):
    full_disk(free=20_000)  # room for the fitted file, not for the report
    refused(cli(*args), "report.png: cannot write: No space left on device", status=1)
    assert not (tmp_path / "report.png").exists() and not (tmp_path / "out.json").exists()  # both or neither
    assert not list(tmp_path.rglob("*.part*"))


def test_the_demo_on_a_full_disk_leaves_no_half_folder(cli, tmp_path, full_disk):
    full_disk(free=450_000)  # its bundled inputs and the fitted pigment fit, the swatch report does not
    refused(cli("demo", "-o", "out", "-q"), "out/swatch-fit.png: cannot write: No space left on device", status=1)
    assert list(tmp_path.iterdir()) == []


def test_a_write_past_a_file_size_limit_in_the_real_process(tmp_path):
    """The operating system's own refusal (EFBIG past RLIMIT_FSIZE; Python ignores SIGXFSZ) through `python -m
    diffwash`: one line, exit 1, nothing left."""

    code = ("import resource, runpy, sys; resource.setrlimit(resource.RLIMIT_FSIZE, (2000, 2000)); "
            "sys.argv = ['diffwash', 'swatches', 'all', '-o', 'chart.png']; runpy.run_module('diffwash', run_name='__main__')")  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT), "DIFFWASH_CACHE_DIR": "off"}
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, r.stderr
    assert r.stderr == "diffwash: error: chart.png: cannot write: File too large; nothing was written\n"
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------------------------
# Numbers: finite in JSON but not in float32, refused with the field's name.


def _scene_with(tmp_path, **changes):
    return write_scene(tmp_path, **changes)


@pytest.mark.parametrize("make, args, needle", [
    (lambda d: _scene_with(d, k_wash=1e39), ["bake", "scene.json", "-o", "lut.png"], "scene.json: k_wash: 1e+39"),
    (lambda d: _scene_with(d, k_wash=1e20, k_specular=1e20), ["bake", "scene.json", "-o", "lut.png"],
     "scene.json: k_wash: k_specular x k_wash = 1e+40"),
    (lambda d: _scene_with(d, camera={"eye": [1e300, 0, 3], "target": [0, 0, 0]}),
     ["render", "scene.json", "-o", "x.png"], "scene.json: camera.eye[0]: 1e+300"),
    (lambda d: _scene_with(d, wash={"K": [1e300, 1, 1], "S": [0, 0, 0]}), ["bake", "scene.json", "-o", "lut.png"],
     "scene.json: wash.K[0]: 1e+300"),
    (lambda d: (d / "p.json").write_text('{"name": "p", "K": [1, 1e300, 1], "S": [0, 0, 0]}'),
     ["swatches", "p.json", "-o", "c.png"], "p.json: K[1]: 1e+300"),
    (lambda d: (d / "lib.json").write_text('{"pigments": [{"name": "a", "K": [1, 1, 1], "S": [0, 0, 0]}, '
                                           '{"name": "b", "K": [1, 1, 1], "S": [0, 0, 1e39]}]}'),
     ["pigments", "--library", "lib.json"], "lib.json: pigments[1].S[2]: 1e+39"),
    (lambda d: (d / "l.json").write_text('{"paper": {"box": [0, 0, 5, 5]}, '
                                         '"patches": [{"box": [5, 5, 9, 9], "coats": 1e39, "ground": "paper"}]}'),
     ["fit-swatch", "card.png", "--layout", "l.json", "-o", "p.json"], "l.json: patches[0].coats: 1e+39"),
    (lambda d: (d / "l.json").write_text('{"paper": {"box": [0, 0, 5, 1e300]}, "patches": []}'),
     ["fit-swatch", "card.png", "--layout", "l.json", "-o", "p.json"], "l.json: paper.box[3]: 1e+300"),
    (lambda d: (d / "t.csv").write_text("pigment,amount,ground,r,g,b\npaper,0,paper,240,240,235\nA,1e39,paper,1,2,3\n"),
     ["fit-swatch", "--table", "t.csv", "-o", "p.json"], "t.csv: line 3: amount: 1e+39"),
    (lambda d: (d / "m.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
                                        "property double z\nelement face 1\nproperty list uchar int vertex_indices\n"
                                        "end_header\n0 0 0\n1e300 0 0\n0 1 0\n3 0 1 2\n") and _scene_with(d, mesh="m.ply"),
     ["render", "scene.json", "-o", "x.png"], "scene.json: mesh: mesh m.ply has non-finite vertex coordinates in float32"),
])  # fmt: skip
def test_numbers_beyond_float32_are_refused_with_their_field(cli, card, tmp_path, make, args, needle):
    make(tmp_path)
    before = snapshot(tmp_path)
    refused(cli(*args), needle)
    assert snapshot(tmp_path) == before


# ---------------------------------------------------------------------------------------------------------------
# Libraries: names that differ only in case or spacing are refused.


@pytest.mark.parametrize("other", ["cadmium red", "CADMIUM  RED ", "Cadmium Red"])
def test_library_names_that_collide_are_refused(cli, tmp_path, other):
    entries = [{"name": "Cadmium Red", "K": [0.1, 1, 1], "S": [0.1, 0.1, 0.1]},
               {"name": "Cobalt Blue", "K": [1, 0.5, 0.1], "S": [0.1, 0.1, 0.1]},
               {"name": other, "K": [0.2, 1, 1], "S": [0.1, 0.1, 0.1]}]  # fmt: skip
    (tmp_path / "lib.json").write_text(json.dumps({"pigments": entries}))
    refused(cli("pigments", "--library", "lib.json"),
            f"lib.json: pigments[2].name: {other.strip()!r} and pigments[0].name 'Cadmium Red' name the same pigment")  # fmt: skip
    refused(cli("swatches", "lib.json", "-o", "c.png"), "pigments[2].name")


# ---------------------------------------------------------------------------------------------------------------
# The demo's folder: its own, new or empty; another folder only with --force.


@pytest.fixture
def quick_demo(monkeypatch):
    """The demo with its six steps replaced by two files (what is tested here is how its folder is written)."""
    import diffwash.demo as demo

    def steps(res, _steps):
        (res.folder / "report.png").write_text("report")
        res.files["report.png"] = res.folder / "report.png"
        (res.folder / "export").mkdir()
        res.files["export/"] = res.folder / "export"

    monkeypatch.setattr(demo, "_run_steps", steps)


def test_demo_refuses_a_folder_it_did_not_write_unless_forced(cli, tmp_path, quick_demo):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "thesis.tex").write_text("years of work")
    (tmp_path / "mine" / "report.png").write_text("my own report")
    before = snapshot(tmp_path)
    refused(cli("demo", "-o", "mine", "-q"), "mine: is not empty", "--force")
    assert snapshot(tmp_path) == before
    code, out, err = cli("demo", "-o", "mine", "-q", "--force")
    assert code == 0, err
    assert (tmp_path / "mine" / "thesis.tex").read_text() == "years of work"  # left alone
    assert (tmp_path / "mine" / "report.png").read_text() == "report"  # the demo's, replaced
    assert not (tmp_path / "mine" / ".diffwash-demo").exists()  # not the demo's folder: a later run refuses it
    refused(cli("demo", "-o", "mine", "-q"), "mine: is not empty")
    (tmp_path / "afile").write_text("x")
    refused(cli("demo", "-o", "afile", "-q"), "afile: exists and is not a folder")


def test_demo_replaces_a_folder_it_wrote(cli, tmp_path, quick_demo):
    for folder in ("new", "empty"):
        if folder == "empty":
            (tmp_path / folder).mkdir()
        code, _, err = cli("demo", "-o", folder, "-q")
        assert code == 0, err
        assert (tmp_path / folder / ".diffwash-demo").is_file() and (tmp_path / folder / "report.png").is_file()
    (tmp_path / "new" / "stale.txt").write_text("from an older demo")
    code, _, err = cli("demo", "-o", "new", "-q")
    assert code == 0, err
    assert sorted(p.name for p in (tmp_path / "new").iterdir()) == [".diffwash-demo", "export", "report.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty", "new"]  # no temporary folder left


# ---------------------------------------------------------------------------------------------------------------
# Usage errors: one line, exit 2.


@pytest.mark.parametrize("args, needle", [
    (["render"], "diffwash render: error: the following arguments are required: SCENE.json, -o/--output"),
    (["bake", "s.json", "-o", "l.png", "--format", "gif"], "--format: invalid choice"),
    (["fit-swatch", "--max-steps", "many", "-o", "p.json"], "--max-steps: invalid int value"),
    (["demo", "--frobnicate"], "unrecognized arguments: --frobnicate"),
])  # fmt: skip
def test_usage_errors_are_one_line(cli, args, needle):
    refused(cli(*args), needle)


# ---------------------------------------------------------------------------------------------------------------
# Special files: only regular files are read, within a size limit checked before reading. A named pipe must not
# block (the test would hang: an alarm fails it instead), a device must not be read until memory runs out.


def _special(tmp_path, kind):
    """A path of `kind`: a named pipe, /dev/zero or a folder."""
    if kind == "fifo":
        os.mkfifo(tmp_path / "special")
        return str(tmp_path / "special")
    if kind == "folder":
        (tmp_path / "special").mkdir()
        return str(tmp_path / "special")
    return "/dev/zero"


def _good_library(folder):
    (folder / "lib.json").write_text(json.dumps({
        "format": "diffwash-library", "version": 1, "observation": {"wavelengths": [400, 500, 600, 700]},
        "pigments": [{"name": "P1", "K": [1.0] * 4, "S": [0.5] * 4}], "grounds": {"paper": [0.8] * 4}}))  # fmt: skip
    (folder / "q.csv").write_text("pigment,amount,ground\nP1,0.01,paper\n")


READERS = {  # reader -> the command reading SPECIAL with it
    "scene": lambda s: ["render", s, "-o", "x.png"],
    "mesh": lambda s: write_scene(Path.cwd(), mesh=s) and ["render", "scene.json", "-o", "x.png"],
    "paper image": lambda s: write_scene(Path.cwd(), watercolour={"paper": {"image": s}}) and
    ["render", "scene.json", "-o", "x.png"],
    "pigment file": lambda s: ["pigments", "--library", s],
    "photo": lambda s: ["fit-swatch", s, "--layout", "card.json", "-o", "p.json"],
    "layout": lambda s: ["fit-swatch", "card.png", "--layout", s, "-o", "p.json"],
    "table": lambda s: ["fit-swatch", "--table", s, "-o", "lib2.json"],
    "library": lambda s: ["predict", s, "--table", "q.csv", "-o", "p.csv"],
    "query table": lambda s: ["predict", "lib.json", "--table", s, "-o", "p.csv"],
}  # fmt: skip
WHAT = {"fifo": "is a named pipe (FIFO), not a regular file", "dev": "is a character device, not a regular file",
        "folder": "is a folder, not a file"}  # fmt: skip


@pytest.mark.parametrize("kind", ["fifo", "dev", "folder"])
@pytest.mark.parametrize("reader", list(READERS))
def test_only_regular_files_are_read(cli, card, tmp_path, reader, kind):
    import signal

    special = _special(tmp_path, kind)
    _good_library(tmp_path)
    args = READERS[reader](special)
    before = snapshot(tmp_path)

    def hung(*_):
        raise AssertionError(f"{reader}: reading a {kind} blocked")

    old = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    try:
        result = cli(*args)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    refused(result, special, WHAT[kind], "reads only regular files")
    assert snapshot(tmp_path) == before


def test_the_file_size_limit_is_checked_before_reading_and_configurable(cli, tmp_path, monkeypatch):
    write_scene(tmp_path)
    size = (tmp_path / "scene.json").stat().st_size
    monkeypatch.setenv("DIFFWASH_MAX_FILE_BYTES", str(size - 1))
    refused(cli("render", "scene.json", "-o", "x.png"), "scene.json", f"is {size:,} bytes", f"limit of {size - 1:,}",
            "DIFFWASH_MAX_FILE_BYTES")  # fmt: skip
    monkeypatch.setenv("DIFFWASH_MAX_FILE_BYTES", "lots")
    refused(cli("render", "scene.json", "-o", "x.png"), "DIFFWASH_MAX_FILE_BYTES", "whole number of bytes")
    assert not (tmp_path / "x.png").exists()


def test_a_negative_seed_is_blamed_on_the_seed(cli, tmp_path):
    refused(cli("swatch-card", "Cadmium Red", "--seed", "-1", "-o", "card.png"), "--seed", ">= 0")
    assert not (tmp_path / "card.png").exists()


@pytest.mark.parametrize("args", [["Cadmium Red"], ["--library", str(ROOT / "data" / "libraries" / "ntu-four.json"),
                                                    "--patches", "P1:1"]])  # fmt: skip
def test_a_seed_past_32_bits_is_refused_as_in_scenes(cli, tmp_path, args):
    refused(cli("swatch-card", *args, "--seed", str(2**32), "-o", "card.png"), "--seed", "< 2^32")
    assert not (tmp_path / "card.png").exists()


@pytest.mark.parametrize("look, needles", [
    ({"strokes": {"length": 1e30}}, ("watercolour.strokes.length", "at most 10 times the mesh's size", "1e+30")),
    ({"paper": {"image": "notes.png"}}, ("watercolour.paper.image", "notes.png", "is not an image diffwash reads")),
    ({"paper": {"density": 1e30}}, ("watercolour.paper.density", "<= 10", "1e+30")),  # rendered non-finite: exit 1
])  # fmt: skip
def test_the_looks_keys_are_refused_before_rendering(cli, tmp_path, look, needles):
    (tmp_path / "notes.png").write_text("a text file, not an image\n")
    write_scene(tmp_path, watercolour=look)
    before = snapshot(tmp_path)
    refused(cli("render", "scene.json", "-o", "x.png"), "scene.json", *needles)
    assert snapshot(tmp_path) == before


# ---------------------------------------------------------------------------------------------------------------
# Memory: large accepted inputs are worked through in blocks, never as whole float64 copies.


def test_a_large_lut_is_encoded_and_written_in_blocks(tmp_path):
    import tracemalloc

    values = np.random.default_rng(0).random((512, 4096, 3), dtype=np.float32)  # 25 MB
    table = diffwash.lut.Lut(values=values, wash_max=1.0, unlit_max=1.0)
    diffwash.lut.encoded(diffwash.lut.Lut(values=values[:2, :2], wash_max=1.0, unlit_max=1.0), "png16")  # imports
    tracemalloc.start()
    try:
        diffwash.lut.save(tmp_path / "lut.png", table)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # Encoded whole, the sRGB encoding alone held a float64 copy (50 MB) and several temporaries (680 MB in all).
    assert peak < values.nbytes, f"saving a {values.nbytes / 2**20:.0f} MB table took {peak / 2**20:.0f} MB"
    back = diffwash.lut.load(tmp_path / "lut.png")
    assert np.array_equal(diffwash.lut.encoded(back, "png16"), diffwash.lut.encoded(table, "png16"))


def test_a_mixture_card_of_many_patches_is_painted_in_blocks(tmp_path):
    # 30 patches over paper and black, 41 bands: painted whole, the card's spectra took 1.4 GB (300 patches, 11 GB).
    patches = ",".join(["P1:1", "P4:2", "P1+P4:1+1", "P8+P10:2+1", "P10:3"] * 6)
    status, err, mb = peak_rss_of(["swatch-card", "--library", DATA / "libraries" / "ntu-four.json", "--patches",
                                   patches, "--ideal", "-o", "card.png"], tmp_path, timeout=300)  # fmt: skip
    assert status == 0, err
    assert mb < 1000, f"a 30-patch mixture card peaked at {mb:.0f} MB"


def test_a_large_photo_is_linearised_in_blocks():
    import tracemalloc

    from diffwash.fit.photos._photo import linearise

    display = np.random.default_rng(1).random((1000, 1000, 3))  # 24 MB
    expected = diffwash.colorimetry.from_display(display[:10])
    tracemalloc.start()
    try:
        linear = linearise(display)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # The result and a block's temporaries: 1.6 times the photo. Decoded whole, the transfer function's float64
    # temporaries took 7 times the photo.
    assert peak < 2 * display.nbytes, f"linearising a {display.nbytes / 2**20:.0f} MB photo took {peak / 2**20:.0f} MB"
    assert np.array_equal(linear[:10], expected)


def test_a_table_too_long_to_fit_is_refused_naming_the_limit(cli, tmp_path, monkeypatch):
    from diffwash.measurements import MAX_TABLE_ROWS, read_measurements

    head, *body = (DATA / "ntu-wpsm" / "ntu-spectral-train.csv").read_text().splitlines()
    rows = [body[i % len(body)] for i in range(MAX_TABLE_ROWS + 500)]
    (tmp_path / "big.csv").write_text("\n".join([head, *rows]) + "\n")
    refused(cli("fit-swatch", "--table", "big.csv", "-o", "lib.json"), f"big.csv: line {MAX_TABLE_ROWS + 2}",
            f"more than {MAX_TABLE_ROWS:,} rows", "DIFFWASH_MAX_TABLE_ROWS=N")  # fmt: skip
    # A one-pigment RGB table too (its own reader, fitted pigment by pigment).
    head_rgb, *body_rgb = (DATA / "examples" / "measurements.csv").read_text().splitlines()
    (tmp_path / "rgb.csv").write_text("\n".join([head_rgb, *(body_rgb * 200)]) + "\n")
    refused(cli("fit-swatch", "--table", "rgb.csv", "-o", "lib.json"), f"rgb.csv: line {MAX_TABLE_ROWS + 2}",
            f"more than {MAX_TABLE_ROWS:,} rows")  # fmt: skip
    monkeypatch.setenv("DIFFWASH_MAX_TABLE_ROWS", "lots")
    refused(cli("fit-swatch", "--table", "big.csv", "-o", "lib.json"), "DIFFWASH_MAX_TABLE_ROWS: must be a whole number")
    assert not (tmp_path / "lib.json").exists()
    # The limit is the environment's, or the reader's argument.
    (tmp_path / "small.csv").write_text("\n".join([head, *body[:20]]) + "\n")
    monkeypatch.setenv("DIFFWASH_MAX_TABLE_ROWS", "19")
    refused(cli("fit-swatch", "--table", "small.csv", "-o", "lib.json"), "small.csv: line 21", "more than 19 rows")
    assert len(read_measurements(tmp_path / "small.csv", max_rows=20).values) == 19  # and the paper's row
    monkeypatch.setenv("DIFFWASH_MAX_TABLE_ROWS", "20")
    assert len(read_measurements(tmp_path / "small.csv").values) == 19


def test_a_paper_image_larger_than_a_tile_is_refused_from_its_header(cli, tmp_path):
    # One tile, repeated over the picture, its textures made at its size: an 8192^2 image took 7.5 GB and 600 s.
    png_bomb(tmp_path / "paper.png", side=8000)
    write_scene(tmp_path, watercolour={"paper": {"image": "paper.png"}})
    status, err, mb = peak_rss_of(["render", "scene.json", "-o", "x.png"], tmp_path, timeout=60)
    refused((status, "", err), "scene.json: watercolour.paper.image", "8000x8000", "over the limit of 4,194,304",
            "crop or scale it to 2048x2048")  # fmt: skip
    assert mb < 800, f"refusing the paper image took {mb:.0f} MB"
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("look", [None, {}])
def test_degenerate_meshes_render_quietly_or_are_refused_in_one_line(cli, tmp_path, look):
    extra = {} if look is None else {"watercolour": look}
    # Some triangles of zero area (a line, a point) among real ones: drawn, without a warning.
    (tmp_path / "some.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\nf 1 1 4\n")
    write_scene(tmp_path, mesh="some.obj", **extra)
    status, _, err = cli("render", "scene.json", "-o", "x.png")
    assert status == 0 and err == "", err
    # Only such triangles: nothing to draw (with the look, a stroke length was blamed on a mesh of size 0).
    for name, text in (("line.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"), ("point.obj", "v 0 0 0\n" * 3 + "f 1 2 3\n")):
        (tmp_path / name).write_text(text)
        write_scene(tmp_path, mesh=name, **extra)
        refused(cli("render", "scene.json", "-o", "y.png"), f"scene.json: mesh: mesh {name} has no triangle of "
                "non-zero area")  # fmt: skip
    assert not (tmp_path / "y.png").exists()
