"""Export a scene for real-time use: the LUT and its sidecar, vertex and fragment shaders for
per-vertex and per-pixel thickness, the mesh as GLB, and viewer.html, a self-contained WebGL2
page showing the mesh with those shaders (orbit with the mouse, move the light, toggle
per-vertex/per-pixel). For a scene with a "watercolour" object it also writes look/, the look's
passes (shaders, textures, passes.json, uniforms.json, README.md), which the viewer draws.
--target threejs also writes diffwash-material.js (an ES module returning a THREE.ShaderMaterial),
index.html (draws mesh.glb with it; serve the folder as static files) and three/ (three.js, MIT).
--target blender also writes blender_scene.py, which builds the scene in Blender (python blender_scene.py
--render OUT.png where Blender's bpy module is installed, or blender -b -P blender_scene.py -- --render
OUT.png), its data blender_data.npz and, where bpy is installed, scene.blend (GLSL 3.30 shader files).
The folder is written whole or not at all.
"""

from __future__ import annotations

from pathlib import Path

import diffwash

from .. import DiffwashError
from .. import io as dio
from .bake import parse_lut_size


def add_arguments(p) -> None:
    p.add_argument("scene", metavar="SCENE.json", help="scene file (a fitted scene file works as it is)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (must not exist or be empty)")
    p.add_argument("--target", choices=list(diffwash.EXPORT_TARGETS), default="webgl2", help="shader language of the .vert/.frag files; threejs adds a three.js module and page, blender a script that builds the scene in Blender and a .blend (default: %(default)s)")
    p.add_argument("--size", default="256", metavar="N", help="LUT samples per axis, 2..4096, or NxM (default: %(default)s)")
    p.add_argument("--format", choices=list(diffwash.LUT_FORMATS), default="png16", help="LUT file format (default: %(default)s)")
    p.add_argument("--rt", action="store_true", help="export the R/T LUT and shaders that composite over a paper uniform")
    p.add_argument("--overwrite", action="store_true", help="replace a previous export in DIR")
    p.add_argument("--partial", action="store_true",
                   help="--target blender: export a watercolour look whose edges, shadow or hatching shader nodes cannot "
                        "draw without them (else such a scene is refused)")  # fmt: skip


def run(args) -> int:
    if args.partial and args.target != "blender":
        raise DiffwashError("goes with --target blender (the other targets draw the whole look)", field="--partial")
    size = parse_lut_size(args.size)
    dio.refuse_overwriting_inputs({"--output": args.output}, [args.scene, *diffwash.referenced_files(args.scene)], folders=["--output"])
    scene = diffwash.load_scene(args.scene)
    written = diffwash.export(
        scene, args.output, target=args.target, size=size, fmt=args.format, kind="rt" if args.rt else "colour", overwrite=args.overwrite,
        partial=args.partial,
    )
    out = Path(args.output)
    top = [w.name for w in written if w.parent == out]
    look = [w for w in written if w.parent != out and w.relative_to(out).parts[0] == "look"]
    three = [w for w in written if w.parent != out and w.relative_to(out).parts[0] == "three"]
    blender = [w.name for w in written if w.name in ("blender_scene.py", "scene.blend")]
    print(
        f"wrote {args.output}/: {', '.join(top)}"
        + (f", look/ ({len(look)} files: the watercolour look's passes, see look/README.md)" if look else "")
        + (f", three/ ({len(three)} files: three.js, MIT)" if three else "")
    )
    print(f"open {args.output}/viewer.html in a browser with WebGL2")
    if three:
        print(f"three.js: serve the folder (python -m http.server -d {args.output}) and open index.html")
    if blender:
        script = out / "blender_scene.py"
        print(f"Blender: python {script} --render OUT.png (with bpy installed), or blender -b -P {script} -- --render OUT.png"
              + ("; or open " + str(out / "scene.blend") if "scene.blend" in blender else ""))
        left = [k for k in diffwash.BLENDER_LEAVES_OUT if scene.watercolour is not None and k in scene.watercolour.effects]
        if left:
            print(f"Blender draws the watercolour look's paper, unevenness, strokes and mix, not its {', '.join(left)} "
                  "(beyond shader nodes: docs/blender.md)")
    return 0
